"""Generic point-cloud outlier filters, offered for comparison (paper 002 §5: they see nothing here).

`knn_mean`: the classic KNN filter — the mean Euclidean distance of each point to its k nearest
neighbours in (x, y, D); points beyond mean + std_ratio·std of that distance are outliers (the rule
of PCL's and open3d's statistical filter). `statistical`: open3d's `remove_statistical_outlier` itself.
On a residual map D is micrometres while x, y are millimetres, so a spike barely changes a point's
Euclidean distances — which is why the paper measures z-distances to an interpolated neighbourhood.
"""
from __future__ import annotations

import numpy as np

# scipy is imported where it is used: a batch's own process validates the recipe without it (issue 17)


def knn_mean_distance(x, y, d, k: int) -> np.ndarray:
    from scipy.spatial import cKDTree

    pts = np.column_stack([x, y, d])
    dist, _ = cKDTree(pts).query(pts, k=k + 1)
    return dist[:, 1:].mean(axis=1)


def statistical_open3d(x, y, d, k: int, std_ratio: float) -> np.ndarray:
    """Boolean mask of the points open3d's statistical filter removes."""
    import open3d as o3d  # lazy: heavy

    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.column_stack([x, y, d])))
    _, kept = pc.remove_statistical_outlier(nb_neighbors=int(k), std_ratio=float(std_ratio))
    mask = np.ones(len(x), dtype=bool)
    mask[np.asarray(kept, dtype=np.int64)] = False
    return mask


def hampel(x, y, d, k: int = 25, n_sigma: float = 8.0) -> np.ndarray:
    """Boolean mask of the points a Hampel filter flags: |D − median of its k nearest neighbours'
    D| > n_sigma · 1.4826 · MAD of those neighbours' D (the point itself not among them)."""
    from scipy.spatial import cKDTree

    pts = np.column_stack([x, y])
    from pointspro.core.parallel import threaded_query

    _, idx = threaded_query(cKDTree(pts), pts, k=k + 1, workers=-1)
    nb = np.asarray(d)[idx[:, 1:]]
    med = np.median(nb, axis=1)
    mad = 1.4826 * np.median(np.abs(nb - med[:, None]), axis=1)
    return np.abs(np.asarray(d) - med) > n_sigma * mad
