"""A batch on a Dask cluster as users start one: paths that travel, checks before the night starts,
and inputs shipped to workers that see no shared folder.

- **The recipe travels as data** (``recipe_bundle``): its text, the ``--set`` overrides and the files
  it names by relative path (calibrations, models, meshes, ``inputs:``) as bytes under their names
  relative to the recipe's folder. A worker writes them into a private temporary folder and parses
  the recipe there, once per recipe version (``bundled_recipe``, keyed by the bundle's SHA-256). The
  temporary folder's name never reaches a report or a message: ``PathMap`` turns it back into the
  names the client's own run would have written, so a cluster's outputs are byte-identical to a
  local run's. Files the recipe names by absolute path are read where they are (the pre-flight
  checks that every worker can read them).
- **Inputs and --out travel as absolute paths**, resolved on the client; the reports and messages
  keep the names as the user typed them (as a local run does).
- **Pre-flight** (``preflight`` on every worker through ``Client.run``, ``check_workers`` on the
  client): the same PointsPro version, the recipe's steps installed from the same distributions and
  versions and loadable, every input and its folder readable and ``--out`` writable (shared-folder
  mode), the recipe's absolute files readable, a temporary folder writable. One line per problem,
  naming the worker, before any input runs.
- **--ship** (``ship_job``): each input's bytes go to the worker (at most ``SHIP_LIMIT`` bytes per
  input) and the output folder's files come back as ``{name: bytes}``; the client writes them with
  ``atomic_dir`` as a local run does.
"""
from __future__ import annotations

import hashlib
import os
import shutil
import socket
import tempfile
import time
from pathlib import Path

from .errors import PointsProError, RecipeError

#: the most bytes one input may have with --ship (it travels through the scheduler's network, and a
#: worker holds it in memory once): 2 GiB
SHIP_LIMIT = 2 * 1024 ** 3

#: seconds within which a scheduler that does not answer is said so
CONNECT_TIMEOUT = 30.0


# --- the recipe as data -----------------------------------------------------------------------------

def named_files(recipe, data=None) -> list[tuple[str, str]]:
    """(where in the recipe, the path as written) of every file the recipe names: a mesh surface's
    ``path``, the ``inputs:`` block (``data``: the recipe's YAML data with --set applied, which keeps
    the paths as written) and the steps' ``file=True`` parameters."""
    from .step import file_parameters

    named = []
    spec = recipe.surface_spec or {}
    if spec.get("type") == "mesh" and isinstance(spec.get("path"), str):
        named.append(("surface: key 'path'", spec["path"]))
    raw_inputs = (data or {}).get("inputs") if isinstance(data, dict) else None
    if isinstance(raw_inputs, dict):
        named += [(f"inputs: key '{k}'", str(v)) for k, v in raw_inputs.items()]
    else:
        named += [(f"inputs: key '{k}'", str(v)) for k, v in recipe.inputs.items()]
    for i, rs in enumerate(recipe.steps, 1):
        named += [(f"step {i} '{rs.id}': parameter '{k}'", v) for k, v in file_parameters(rs.params).items()]
    return named


def recipe_bundle(recipe_path: Path, recipe, overrides=()) -> dict:
    """The recipe as plain data for the workers (see the module's text). ``recipe_path``: as the user
    typed it (the reports name parameter files relative to it, as a local run's do)."""
    from .yamlio import load_yaml

    recipe_path = Path(recipe_path)
    try:
        text = recipe_path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise RecipeError(f"{recipe_path}: cannot read the recipe ({e})") from None
    data = load_yaml(text, str(recipe_path))
    here = Path(os.path.abspath(recipe_path.parent))
    files: dict[Path, Path] = {}  # lexical absolute path → the path read (links followed by the OS)
    absolute: list[str] = []
    for _what, value in named_files(recipe, data):
        p = Path(value)
        if p.is_absolute():
            absolute.append(str(p))  # read where it is; the pre-flight checks the workers can
            continue
        full = Path(os.path.abspath(here / p))
        if full.is_file():
            files[full] = here / p
    root = Path(os.path.commonpath([here, *(f.parent for f in files)])) if files else here
    payload = {str(f.relative_to(root)): src.read_bytes() for f, src in sorted(files.items())}
    name = str((here / recipe_path.name).relative_to(root))
    h = hashlib.sha256()
    for part in (name, text, *map(str, overrides)):
        h.update(part.encode("utf-8") + b"\0")
    for k, v in sorted(payload.items()):
        h.update(k.encode("utf-8") + b"\0" + hashlib.sha256(v).digest())
    shown_dir = recipe_path.parent
    return {"hash": h.hexdigest(), "name": name, "text": text, "files": payload,
            "overrides": [str(o) for o in overrides], "absolute": absolute,
            # what the client's own run calls the recipe's folder and the bundle's root
            "shown_dir": "" if str(shown_dir) == "." else str(shown_dir), "root": str(root)}


class PathMap:
    """Turns a worker's private paths back into the client's names, in strings and in the reports'
    nested dicts and lists. ``pairs``: (worker's, client's) prefixes, the most specific first."""

    def __init__(self, pairs):
        self.pairs = [(a, b) for a, b in pairs if a and a != b]

    def text(self, s):
        if not isinstance(s, str):
            return s
        for a, b in self.pairs:
            if a in s:
                s = s.replace(a, b)
        return s

    def deep(self, obj):
        if isinstance(obj, str):
            return self.text(obj)
        if isinstance(obj, dict):
            return {self.text(k): self.deep(v) for k, v in obj.items()}
        if isinstance(obj, list):
            return [self.deep(v) for v in obj]
        if isinstance(obj, tuple):
            return tuple(self.deep(v) for v in obj)
        return obj

    def then(self, pairs) -> "PathMap":
        """This map with ``pairs`` tried first (e.g. one input's read path → its name as typed)."""
        return PathMap([*pairs, *self.pairs])


_BUNDLES: dict[str, tuple] = {}  # hash → (recipe, surface, folder, PathMap); a worker's cache
_KEEP = 4


def bundled_recipe(bundle: dict):
    """(Recipe, nominal surface, PathMap) of a recipe bundle in this worker: the files written into
    a private temporary folder and the recipe parsed there, once per bundle (its hash). A cache, not
    state: the same hash always gives the same recipe, and steps never modify it."""
    got = _BUNDLES.get(bundle["hash"])
    if got is not None:
        return got[0], got[1], got[3]
    from .batch import load_batch_recipe

    folder = Path(tempfile.mkdtemp(prefix="pointspro-recipe-"))
    try:
        for rel, data in bundle["files"].items():
            target = folder / rel
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_bytes(data)
        path = folder / bundle["name"]
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(bundle["text"], encoding="utf-8")
        here = str(path.parent)
        shown = bundle["shown_dir"]
        pmap = PathMap([(here + os.sep, shown + os.sep if shown else ""), (here, shown or "."),
                        (str(folder) + os.sep, bundle["root"].rstrip(os.sep) + os.sep),
                        (str(folder), bundle["root"])])
        try:
            recipe = load_batch_recipe(path, tuple(bundle["overrides"]))
            surface = recipe.build_surface() if recipe.surface_spec is not None else None
        except PointsProError as e:
            raise type(e)(pmap.text(str(e))) from None
    except BaseException:
        shutil.rmtree(folder, ignore_errors=True)
        raise
    if not _BUNDLES:
        import atexit

        atexit.register(_remove_bundles)  # the worker's temporary folders go with it
    while len(_BUNDLES) >= _KEEP:  # the oldest recipe version goes, with its folder
        old = _BUNDLES.pop(next(iter(_BUNDLES)))
        shutil.rmtree(old[2], ignore_errors=True)
    _BUNDLES[bundle["hash"]] = (recipe, surface, folder, pmap)
    return recipe, surface, pmap


def _remove_bundles() -> None:
    while _BUNDLES:
        shutil.rmtree(_BUNDLES.popitem()[1][2], ignore_errors=True)


def bundle_folder(bundle: dict) -> str | None:
    """This worker's temporary folder of a bundle already parsed (a parameter file may lie there)."""
    got = _BUNDLES.get(bundle["hash"])
    return None if got is None else str(got[2])


# --- one input on a worker --------------------------------------------------------------------------

def cluster_job(bundle: dict, path: str, shown: str, out_dir: str, stem: str, allowed_dirs, figures: str,
                options: dict | None = None, data: bytes | None = None, cancel_event: str | None = None):
    """One input on a Dask worker. ``path``: the input's absolute path (shared-folder mode) or its
    file name (``data``, --ship: its bytes); ``shown``: its name as the user typed it. Returns the
    InputOutcome; with --ship a tuple (outcome, {relative name: bytes} of its output folder).
    ``options["cwd"]``: the client's working folder (--ship: the input's absolute path recorded
    for --resume is the client's).
    ``cancel_event``: the name of a Dask Event the client sets on Ctrl-C — the input then stops at
    its next progress update and leaves no temporary folder."""
    from .batch import capture_log, failed_outcome, process_input

    options = options or {}
    ship = data is not None
    work = Path(tempfile.mkdtemp(prefix="pointspro-input-")) if ship else None
    files, pmap = None, None
    try:
        with capture_log(options.get("log_level")) as records:
            try:
                recipe, surface, pmap = bundled_recipe(bundle)
            except Exception as e:  # noqa: BLE001 — one line for this input, like any other failure
                oc = failed_outcome(shown, "reading the recipe in the worker", e)
            else:
                read = Path(path)
                out = Path(out_dir)
                if ship:
                    read = work / "in" / Path(path).name
                    read.parent.mkdir()
                    read.write_bytes(data)
                    out = work / "out"
                    out.mkdir()
                # report.json's input_abspath, as the client's own run records it: the client's
                # absolute path (shared folders), or --ship: its name made absolute in its folder
                absolute = str(read) if not ship else (
                    os.path.normpath(os.path.join(options["cwd"], shown)) if options.get("cwd") else None)
                pmap = pmap.then([(str(read), shown)])
                allowed = [Path(d) for d in allowed_dirs] + [Path(bundle_folder(bundle))] \
                    if allowed_dirs is not None else None
                token = _EventToken(cancel_event) if cancel_event else None
                oc = process_input(read, recipe, out, stem, surface=surface, figures=figures,
                                   allowed_dirs=allowed, cloud_format=options.get("cloud_format", "csv"),
                                   overrides=tuple(bundle["overrides"]), shown=shown, token=token,
                                   paths=pmap, absolute=absolute)
                oc.error, oc.traceback = pmap.text(oc.error), pmap.text(oc.traceback)
                if ship and oc.ok:
                    folder = out / stem
                    files = {str(p.relative_to(folder)): p.read_bytes()
                             for p in sorted(folder.rglob("*")) if p.is_file()}
        oc.log = [{**r, "msg": pmap.text(r["msg"])} for r in records] if pmap is not None else records
    finally:
        if work is not None:
            shutil.rmtree(work, ignore_errors=True)
    return (oc, files) if ship else oc


class _EventToken:
    """A CancelToken whose flag is a Dask Event the client sets (asked at most twice a second)."""

    def __init__(self, name: str):
        self.name, self._next, self._set = name, 0.0, False

    def cancel(self):
        self._set = True

    @property
    def cancelled(self) -> bool:
        if not self._set and time.monotonic() >= self._next:
            self._next = time.monotonic() + 0.5
            try:
                from distributed import Event

                self._set = Event(self.name).is_set()
            except Exception:  # noqa: BLE001 — no scheduler to ask: keep going
                pass
        return self._set


def write_shipped(out_dir: Path, stem: str, files: dict) -> None:
    """The output folder a worker sent back, written as a local run writes it: into a temporary
    folder renamed to ``out_dir/stem`` when complete."""
    from .io import atomic_dir

    with atomic_dir(Path(out_dir) / stem) as tmp:
        for rel, data in files.items():
            parts = Path(rel).parts
            if not parts or Path(rel).is_absolute() or ".." in parts:
                raise RecipeError(f"{rel}: a worker sent a file name outside the output folder")
            target = tmp.joinpath(*parts)
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_bytes(data)


def cleanup_stems(out_dir: Path, stems) -> list[str]:
    """Remove the temporary folders (``.<stem>.<8 hex>.partial``, ``.old``) a lost worker left for these
    stems; a worker that died mid-input cannot remove its own (``batch.cleanup_partials``: these
    stems' alone, not those of an input whose name starts the same)."""
    from .batch import cleanup_partials

    return cleanup_partials(out_dir, stems)


# --- pre-flight --------------------------------------------------------------------------------------

def step_versions(ids) -> dict[str, str]:
    """``{step id: "distribution version"}`` of the installed steps among ``ids`` (built-in steps
    too: they are entry points of pointspro's own distribution)."""
    from importlib.metadata import entry_points

    from .registry import GROUP

    eps = {ep.name: ep for ep in entry_points(group=GROUP)}
    out = {}
    for i in ids:
        ep = eps.get(i)
        if ep is not None:
            dist = getattr(ep, "dist", None)
            out[i] = f"{dist.name} {dist.version}" if dist is not None else ep.value
    return out


def expectations(recipe, bundle: dict, inputs, out_dir: Path, ship: bool) -> dict:
    """What every worker must have and see (plain values): this machine's PointsPro version and the
    recipe's steps, and in shared-folder mode the inputs and --out (absolute)."""
    from . import __version__

    ids = sorted({rs.id for rs in recipe.steps})
    return {"version": __version__, "steps": step_versions(ids), "ids": ids, "ship": ship,
            "inputs": [] if ship else [str(Path(p).absolute()) for p in inputs],
            "out": None if ship else str(Path(out_dir).absolute()),
            "absolute": list(bundle.get("absolute", []))}


def preflight(expect: dict) -> list[str]:
    """Run on a worker: the problems it has with ``expect`` (``expectations``), one line each."""
    from . import __version__
    from .registry import Registry

    problems = []
    if __version__ != expect["version"]:
        problems.append(f"PointsPro {__version__} is installed there, {expect['version']} here")
    have = step_versions(expect["ids"])
    reg = Registry()
    for i in expect["ids"]:
        want = expect["steps"].get(i)
        if i not in have:
            problems.append(f"step '{i}' is not installed there" + (f" ({want} here)" if want else ""))
            continue
        if want is not None and have[i] != want:
            problems.append(f"step '{i}' is {have[i]} there, {want} here")
            continue
        try:
            reg.load(i)
        except Exception as e:  # noqa: BLE001 — a broken install: say what it raised
            problems.append(f"step '{i}' does not load there ({type(e).__name__}: {e})")
    folders: dict[str, list[str]] = {}
    for p in expect["inputs"]:
        folders.setdefault(os.path.dirname(p), []).append(p)
    for d, files in folders.items():
        if not (os.path.isdir(d) and os.access(d, os.R_OK | os.X_OK)):
            problems.append(f"cannot read the input folder {d}")
            continue
        missing = [f for f in files if not (os.path.isfile(f) and os.access(f, os.R_OK))]
        if missing:
            more = f" and {len(missing) - 1} more" if len(missing) > 1 else ""
            problems.append(f"cannot read the input {missing[0]}{more}")
    if expect["out"] is not None:
        why = _writable(Path(expect["out"]))
        if why:
            problems.append(f"cannot write the output folder {expect['out']} ({why})")
    for f in expect["absolute"]:
        if not (os.path.isfile(f) and os.access(f, os.R_OK)):
            problems.append(f"cannot read {f}, which the recipe names")
    why = _writable(Path(tempfile.gettempdir()))
    if why:
        problems.append(f"cannot write its temporary folder {tempfile.gettempdir()} ({why})")
    return problems


def _writable(folder: Path) -> str | None:
    """None when a file can be created (and removed) in ``folder``, else why not."""
    from .io.atomic import make_temp_file

    if not folder.is_dir():
        return "no such folder"
    try:
        tmp = make_temp_file(folder / f"pointspro-preflight-{socket.gethostname()}")
        os.unlink(tmp)
    except OSError as e:
        return e.strerror or str(e)
    return None


def check_workers(client, expect: dict) -> list[str]:
    """The pre-flight on every worker of ``client``'s cluster: one line per problem, naming the
    worker (its address and host). No worker at all is a problem too."""
    workers = client.scheduler_info().get("workers", {})
    if not workers:
        return [f"scheduler {client.scheduler.address}: no workers are connected (start some with "
                f"`dask worker {client.scheduler.address} --nthreads 1`)"]
    got = client.run(preflight, expect, on_error="return")
    lines = []
    for addr, res in sorted(got.items()):
        host = (workers.get(addr) or {}).get("host") or ""
        who = f"worker {addr}" + (f" ({host})" if host and host not in addr else "")
        if isinstance(res, BaseException):
            why = (f"PointsPro is not installed there ({res})" if isinstance(res, ImportError)
                   else f"the check failed there ({type(res).__name__}: {res})")
            lines.append(f"{who}: {why}")
        else:
            lines += [f"{who}: {p}" for p in res]
    return lines


def probe_scheduler(address: str, timeout: float = CONNECT_TIMEOUT) -> None:
    """A plain TCP connection to a ``tcp://host:port`` scheduler first: an address where nothing
    listens is said at once (Dask's client would retry until its timeout). One line naming it."""
    from urllib.parse import urlsplit

    addr = address if "://" in address else f"tcp://{address}"
    u = urlsplit(addr)
    if u.scheme not in ("tcp", "tls") or not u.hostname:
        return
    try:
        port = u.port or 8786
    except ValueError:
        raise PointsProError(f"--scheduler {address}: not an address (write tcp://HOST:8786)") from None
    try:
        socket.create_connection((u.hostname, port), timeout=timeout).close()
    except OSError as e:
        why = "timed out" if isinstance(e, TimeoutError) else (e.strerror or str(e))
        raise PointsProError(f"--scheduler {address}: no Dask scheduler answers there ({why}); start "
                             "one with `dask scheduler` or check the address") from None


def check_ship_sizes(inputs, limit: int | None = None) -> None:
    """--ship: every input at most ``limit`` bytes (one line naming the first larger one). A missing
    input is not refused here: it fails alone, as in a local run."""
    limit = SHIP_LIMIT if limit is None else limit
    for p in inputs:
        try:
            size = os.stat(p).st_size
        except OSError:
            continue
        if size > limit:
            raise PointsProError(f"{p}: {_size(size)} is more than --ship sends ({_size(limit)} per "
                                 "input); put the inputs in a folder the workers share and run "
                                 "without --ship")


def _size(n: int) -> str:
    for f, unit in ((1024 ** 3, "GiB"), (1024 ** 2, "MiB"), (1024, "KiB")):
        if n >= f:
            return f"{n / f:.3g} {unit}"
    return f"{n} bytes"

