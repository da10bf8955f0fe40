"""Error against ms per frame, one PNG per model (matplotlib, the ``bench`` extra)."""

from __future__ import annotations

from pathlib import Path

from ..errors import missing_extra
from .configs import METHODS
from .curves import FAMILIES, family_front, family_points

__all__ = ["plot_curves", "ERROR_FLOOR"]

#: Errors below this are drawn at it (log axis; the ray caster's error can be 0).
ERROR_FLOOR = 1e-6
#: Colour and marker of each method's series (:attr:`~plantgen.table1.configs.Method.style`),
#: and of the RC+R sweeps other than "linear" (:data:`plantgen.table1.configs.RELIEF_SWEEPS`);
#: a knob not listed takes the next of :data:`_EXTRA_STYLES` in order of appearance.
_STYLES = {**{m.name: m.style for m in METHODS}, "RC+R binary": ("tab:purple", "v"), "RC+R v": ("tab:brown", "*")}
_EXTRA_STYLES = (("tab:pink", "P"), ("tab:olive", "X"), ("tab:gray", "h"), ("gold", "d"))


def _shown(error: float) -> float:
    return max(error, ERROR_FLOOR)


def _style(label: str, extra: list) -> tuple[str, str]:
    """(colour, marker) of a series label such as ``GS+R`` or ``RC+R binary``; ``extra``
    collects the labels without a listed style, in order."""
    if label in _STYLES:
        return _STYLES[label]
    if label not in extra:
        extra.append(label)
    return _EXTRA_STYLES[extra.index(label) % len(_EXTRA_STYLES)]


def _series(points: list[dict]) -> dict:
    """{label: points}: one series per method, and per knob of a method with several."""
    series = {}
    for c in points:
        label = c["method"] if c["knob"] in ("", "m") else f"{c['method']} {c['knob']}"
        series.setdefault(label, []).append(c)
    return series


def _plot_family(ax, model: str, family: str, points: list[dict], size) -> None:
    extra: list = []
    for label, cs in _series(points).items():
        color, marker = _style(label, extra)
        cs = sorted(cs, key=lambda c: c["ms"])
        ax.plot([c["ms"] for c in cs], [_shown(c["error"]) for c in cs], marker=marker,
                color=color, linestyle="-" if len(cs) > 1 else "none", label=label, alpha=0.8)
        for c in cs:
            ax.annotate(str(c["value"]), (c["ms"], _shown(c["error"])), fontsize=6,
                        textcoords="offset points", xytext=(3, 3))
    front = family_front(points)
    front_ms = [points[i]["ms"] for i in front]
    front_error = [_shown(points[i]["error"]) for i in front]
    ax.step(front_ms, front_error, where="post", color="black", linewidth=1.2, linestyle="--",
            label="Pareto front")
    ax.scatter(front_ms, front_error, s=80, facecolors="none", edgecolors="black")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(f"ms per frame (median, {size[0]}x{size[1]})")
    ax.set_ylabel("error: (1 - SSIM) + silhouette mismatch (floor 1e-6)")   # ERROR_FLOOR
    ax.set_title(f"{model}, {'relief' if family == 'relief' else 'no relief'}: "
                 "error vs time", fontsize=9)
    ax.legend(fontsize=7)
    ax.grid(True, which="both", alpha=0.3)


def plot_curves(results: dict, out_dir: Path) -> list[Path] | str:
    """Error against ms per frame, one PNG per model, Pareto front marked. Returns the
    paths, or a message when matplotlib (the ``bench`` extra) is missing."""
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return missing_extra("drawing the curves (matplotlib)", "bench") + "; curves written as CSV only"
    written = []
    for m in results["models"]:
        families = [f for f in FAMILIES if family_points(m, f)]
        if not families:
            continue
        fig, axes = plt.subplots(1, len(families), figsize=(6.5 * len(families), 4.5), dpi=110,
                                 squeeze=False)
        for ax, family in zip(axes[0], families, strict=True):
            _plot_family(ax, m["model"], family, family_points(m, family), results["options"]["size"])
        fig.suptitle(results["machine"]["gl_renderer"] + " · " + results["machine"]["date_utc"], fontsize=8)
        path = out_dir / f"curves_{m['model']}.png"
        fig.tight_layout()
        fig.savefig(path)
        plt.close(fig)
        written.append(path)
    return written
