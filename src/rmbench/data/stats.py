"""Feature statistics in LeRobot's layout: min, max, mean, std and count per feature.

Each episode carries its own statistics (columns ``stats/<feature>/<stat>`` of its
meta/episodes row); meta/stats.json aggregates them exactly (pooled mean and variance), so it
can be rebuilt from the committed episodes alone after an interrupted collection.
"""

from __future__ import annotations

import numpy as np

STAT_NAMES = ("min", "max", "mean", "std", "count")


def array_stats(x: np.ndarray) -> dict[str, np.ndarray]:
    """Statistics over the first axis of a (T, ...) array."""
    x = np.asarray(x, np.float64)
    if x.ndim == 1:
        x = x[:, None]
    return {"min": x.min(0), "max": x.max(0), "mean": x.mean(0), "std": x.std(0),
            "count": np.array([len(x)])}


def pop_stats(row: dict) -> dict[str, dict[str, np.ndarray]]:
    """Take an episode's statistics out of its meta/episodes ``row`` (its ``stats/<feature>/
    <stat>`` columns): {feature: {stat: array}}."""
    stats: dict[str, dict[str, np.ndarray]] = {}
    for col in [c for c in row if c.startswith("stats/")]:
        _, key, stat = col.split("/")  # feature names hold no "/"
        stats.setdefault(key, {})[stat] = np.asarray(row.pop(col))
    return stats


def aggregate(per_episode: list[dict[str, dict[str, np.ndarray]]]) -> dict[str, dict[str, np.ndarray]]:
    """Combine per-episode statistics of the same features into dataset statistics."""
    if not per_episode:
        return {}
    out = {}
    for key in per_episode[0]:
        parts = [ep[key] for ep in per_episode]
        counts = np.array([float(np.asarray(p["count"]).reshape(-1)[0]) for p in parts])
        w = counts / counts.sum()
        shape = np.asarray(parts[0]["mean"]).shape
        means = np.stack([np.asarray(p["mean"], np.float64) for p in parts])
        stds = np.stack([np.asarray(p["std"], np.float64) for p in parts])
        wb = w.reshape((-1,) + (1,) * len(shape))
        mean = (wb * means).sum(0)
        var = (wb * (stds ** 2 + (means - mean) ** 2)).sum(0)
        out[key] = {"min": np.min([np.asarray(p["min"]) for p in parts], axis=0),
                    "max": np.max([np.asarray(p["max"]) for p in parts], axis=0),
                    "mean": mean, "std": np.sqrt(np.maximum(var, 0.0)),
                    "count": np.array([int(counts.sum())])}
    return out


def to_json(stats: dict[str, dict[str, np.ndarray]]) -> dict:
    return {k: {s: np.asarray(v).tolist() for s, v in d.items()} for k, d in stats.items()}


def from_json(raw: dict) -> dict[str, dict[str, np.ndarray]]:
    return {k: {s: np.asarray(v) for s, v in d.items()} for k, d in raw.items()}
