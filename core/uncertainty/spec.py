"""The recipe's ``uncertainty:`` block, validated before any file is read (docs/uncertainty.md).

    uncertainty:
      samples: 200            # Monte Carlo trials M (JCGM 101 §7.2), at least MIN_SAMPLES
      seed: 1                 # the samples' random numbers; same seed, same result, any worker count
      noise: auto             # or "50 nm": σ of the measurement noise along the measuring axis
      sources:                # type-B inputs, each a standard uncertainty with its unit
        probe_radius: "0.5 um"               # the probe_radius step's ball (stylus tip) radius
        z_scale: "50 ppm"                    # the measuring axis's scale: z·(1 + ε)
        length_scale: "2 ppm"                # all three axes: x, y, z·(1 + ε)
        temperature: {u: "0.2 K", cte: "2.6 ppm/K"}   # x, y, z·(1 + α·ΔT)
      workers: 2              # processes (default: the cores this process may use)

Every uncertainty is written with its unit; a bare number is refused, naming the key and the units
accepted. Errors are one line: "recipe.yaml, line 14: uncertainty: key 'sources.z_scale': …".
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

from ..errors import RecipeError

#: JCGM 101 §7.2.2 asks M ≫ 1/(1 − p) = 20 for p = 95 %; below 50 samples the 2.5 % end of the
#: interval would rest on a single sample
MIN_SAMPLES = 50
MAX_SAMPLES = 100_000
COVERAGE = 0.95

LENGTH_UNITS = {"nm": 1e-6, "um": 1e-3, "µm": 1e-3, "μm": 1e-3, "mm": 1.0}
RATIO_UNITS = {"ppm": 1e-6, "ppb": 1e-9, "%": 1e-2}
TEMPERATURE_UNITS = {"K": 1.0, "mK": 1e-3}
CTE_UNITS = {"ppm/K": 1e-6, "1/K": 1.0, "/K": 1.0}

KEYS = ("samples", "seed", "noise", "sources", "workers")
#: source → (kind of quantity, the step it needs or None)
SOURCES = {"probe_radius": ("length", "probe_radius"), "z_scale": ("ratio", None),
           "length_scale": ("ratio", None), "temperature": ("temperature", None)}
_NUMBER = re.compile(r"^\s*([+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)\s*(\S.*?)?\s*$")


@dataclass(frozen=True)
class Source:
    """One type-B input: its name, standard uncertainty (in ``unit``'s base: mm, 1, K) and the text."""

    name: str
    u: float
    text: str
    #: for temperature: the expansion coefficient (1/K) and its text
    cte: float | None = None
    cte_text: str | None = None

    @property
    def relative(self) -> float | None:
        """The standard uncertainty of the scale factor (1) of a scale source; None for probe_radius."""
        if self.name in ("z_scale", "length_scale"):
            return self.u
        if self.name == "temperature":  # u(α·ΔT) = |α|·u(ΔT): α may be negative (Zerodur, ULE)
            return self.u * abs(self.cte)
        return None

    def to_dict(self):
        if self.name == "temperature":
            return {"u": self.text, "cte": self.cte_text}
        return self.text


@dataclass(frozen=True)
class UncertaintySpec:
    samples: int = 200
    seed: int = 1
    #: σ of the noise (mm) or None for auto (estimated from the data: core.uncertainty.noise)
    noise: float | None = None
    noise_text: str = "auto"
    sources: tuple[Source, ...] = ()
    workers: int | None = None
    #: (key, line) of each source for messages raised later (a recipe edited in the window)
    lines: dict = field(default_factory=dict, compare=False)

    def to_dict(self) -> dict:
        d = {"samples": self.samples, "seed": self.seed, "noise": self.noise_text}
        if self.sources:
            d["sources"] = {s.name: s.to_dict() for s in self.sources}
        if self.workers is not None:
            d["workers"] = self.workers
        return d

    def check_steps(self, steps, at: str) -> None:
        """A source that needs a step the recipe lacks (probe_radius without its step): one line."""
        ids = {s.id for s in steps if getattr(s, "enabled", True)}
        if "dynamic" in ids:
            # the samples add noise to z, which dynamic rebuilds from its xd and xc channels: every
            # sample failed, or (tiny noise) the noise vanished and u read 4e-15 µm (a review)
            raise RecipeError(f"{at}: uncertainty: the Monte Carlo perturbs the heights z, which the "
                              "recipe's 'dynamic' step rebuilds from its xd and xc channels — not supported "
                              "with dynamic (state its uncertainty from repeated scans)")
        for s in self.sources:
            need = SOURCES[s.name][1]
            if need is not None and need not in ids:
                raise RecipeError(f"{self.lines.get(s.name, at)}: uncertainty: key 'sources.{s.name}': the "
                                  f"recipe has no enabled '{need}' step whose parameter it would perturb")


def _where(node, key, at: str, where: str) -> str:
    ln = getattr(node, "key_lines", {}).get(key)
    return f"{where}, line {ln}" if ln else at


def _quantity(value, units: dict, key: str, loc: str, what: str, signed: bool = False) -> tuple[float, str]:
    accepted = ", ".join(units)
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise RecipeError(f"{loc}: uncertainty: key '{key}': {value!r} is not {what} — write it with its "
                          f"unit, e.g. \"0.5 {next(iter(units))}\" (units: {accepted})")
    if isinstance(value, (int, float)):
        raise RecipeError(f"{loc}: uncertainty: key '{key}': {value!r} has no unit — write "
                          f"\"{value} {next(iter(units))}\" or another unit ({accepted})")
    m = _NUMBER.match(value)
    if not m or m.group(2) is None:
        raise RecipeError(f"{loc}: uncertainty: key '{key}': {value!r} is not a number with a unit "
                          f"(units: {accepted})")
    unit = m.group(2)
    if unit not in units:
        raise RecipeError(f"{loc}: uncertainty: key '{key}': unit {unit!r} is not one of {accepted} "
                          f"({what})")
    v = float(m.group(1)) * units[unit]
    if signed and not math.isfinite(v):
        raise RecipeError(f"{loc}: uncertainty: key '{key}': {what} is a finite number (got {value!r})")
    if not signed and (not math.isfinite(v) or v < 0):
        raise RecipeError(f"{loc}: uncertainty: key '{key}': a standard uncertainty is a finite number "
                          f"≥ 0 (got {value!r})")
    return v, f"{m.group(1)} {unit}"


def _integer(value, key: str, loc: str, lo: int, hi: int, why: str = "") -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise RecipeError(f"{loc}: uncertainty: key '{key}': an integer is needed (got {value!r})")
    if not lo <= value <= hi:
        raise RecipeError(f"{loc}: uncertainty: key '{key}': {value} is outside {lo}…{hi}{why}")
    return value


def parse_uncertainty(data, at: str, where: str, steps=None) -> UncertaintySpec:
    """The validated block (``at``: "recipe.yaml, line 12" of the key; ``where``: the file); with
    ``steps``, a source needing a step the recipe lacks is refused too."""
    if data is True or data == {}:
        data = {}
    if not isinstance(data, dict):
        raise RecipeError(f"{at}: uncertainty: must be a mapping, e.g. {{samples: 200, seed: 1}}")
    for key in data:
        if key not in KEYS:
            raise RecipeError(f"{_where(data, key, at, where)}: uncertainty: unknown key '{key}' (it has "
                              f"{', '.join(KEYS)})")
    loc = lambda k: _where(data, k, at, where)  # noqa: E731
    samples = data.get("samples", 200)
    samples = _integer(samples, "samples", loc("samples"), 1, MAX_SAMPLES)
    if samples < MIN_SAMPLES:
        raise RecipeError(f"{loc('samples')}: uncertainty: key 'samples': {samples} Monte Carlo samples are "
                          f"too few for a 95 % coverage interval — JCGM 101 §7.2.2 asks M ≫ 1/(1 − p) = 20; "
                          f"give at least {MIN_SAMPLES} (200 or more recommended)")
    seed = _integer(data.get("seed", 1), "seed", loc("seed"), 0, 2**63 - 1)
    workers = data.get("workers")
    if workers is not None:
        workers = _integer(workers, "workers", loc("workers"), 1, 1024)
    noise = data.get("noise", "auto")
    if noise == "auto":
        sigma, noise_text = None, "auto"
    else:
        sigma, noise_text = _quantity(noise, LENGTH_UNITS, "noise", loc("noise"),
                                      "a length (σ of the noise along the measuring axis) or auto")
        if sigma == 0:  # every sample would be the nominal run: U95 ~1e-18, a "proof" of conformity
            raise RecipeError(f"{loc('noise')}: uncertainty: key 'noise': σ = 0 makes every Monte Carlo "
                              "sample the same run — give the σ a repeatability test measured, or auto")
    sources_in = data.get("sources") or {}
    if not isinstance(sources_in, dict):
        raise RecipeError(f"{loc('sources')}: uncertainty: key 'sources': a mapping of source: standard "
                          f"uncertainty, e.g. {{probe_radius: \"0.5 um\"}} (sources: {', '.join(SOURCES)})")
    sources, lines = [], {}
    for name, value in sources_in.items():
        sl = _where(sources_in, name, loc("sources"), where)
        lines[name] = sl
        if name not in SOURCES:
            raise RecipeError(f"{sl}: uncertainty: key 'sources.{name}': unknown source (the sources are "
                              f"{', '.join(SOURCES)})")
        kind = SOURCES[name][0]
        key = f"sources.{name}"
        if kind == "length":
            u, text = _quantity(value, LENGTH_UNITS, key, sl, "a length")
            sources.append(Source(name, u, text))
        elif kind == "ratio":
            u, text = _quantity(value, RATIO_UNITS, key, sl, "a relative scale error")
            sources.append(Source(name, u, text))
        else:
            if not isinstance(value, dict) or set(value) != {"u", "cte"}:
                raise RecipeError(f"{sl}: uncertainty: key '{key}': give {{u: \"0.2 K\", cte: \"2.6 ppm/K\"}} "
                                  "(the temperature's standard uncertainty and the part's expansion coefficient)")
            u, text = _quantity(value["u"], TEMPERATURE_UNITS, key + ".u", _where(value, "u", sl, where),
                                "a temperature")
            # signed: a glass ceramic's coefficient may be below zero (Zerodur, ULE: ±0.02 ppm/K)
            cte, cte_text = _quantity(value["cte"], CTE_UNITS, key + ".cte", _where(value, "cte", sl, where),
                                      "an expansion coefficient", signed=True)
            sources.append(Source(name, u, text, cte, cte_text))
    spec = UncertaintySpec(samples, seed, sigma, noise_text, tuple(sources), workers, lines)
    if steps is not None:
        spec.check_steps(steps, at)
    return spec
