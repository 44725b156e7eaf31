"""Run.plot's figure, drawn from the run's DataFrames."""

from __future__ import annotations


def draw(plt, run):
    """The sweep's figure: for one parameter the stroboscopic points (when
    kept) above the exponents; for two, the largest exponent over the grid."""
    spectrum = run.spectrum
    if spectrum is None:
        # A run without exponents (output.lyapunov = "none"): the diagram
        # alone, as the command line draws it.
        if run.bifurcation is None:
            raise ValueError(
                "the run kept neither exponents (output.lyapunov = \"none\") nor points: nothing to plot"
            )
        return _points_alone(plt, run)
    # The swept parameters head the columns, the exponents follow.
    if not spectrum.columns[1].startswith("lambda_"):
        return _grid(plt, spectrum)
    parameter = spectrum.columns[0]
    panels = 2 if run.bifurcation is not None else 1
    fig, axes = plt.subplots(panels, 1, sharex=True, squeeze=False, figsize=(8, 3 + 2.5 * panels))
    axes = axes[:, 0]
    if run.bifurcation is not None:
        points = run.bifurcation
        state = points.columns[1]
        axes[0].plot(points[parameter], points[state], ",k")
        axes[0].set_ylabel(state)
    exponents = [c for c in spectrum.columns if c.startswith("lambda_") and c[7:].isdigit()]
    # With many starts a value has a row per start: points, not lines.
    style = "." if spectrum[parameter].duplicated().any() else "-"
    for column in exponents:
        axes[-1].plot(spectrum[parameter], spectrum[column], style, ms=2, label=_label(column))
    axes[-1].axhline(0.0, color="grey", lw=0.5)
    axes[-1].set_xlabel(parameter)
    axes[-1].set_ylabel("exponent")
    axes[-1].legend(loc="best", fontsize="small")
    fig.suptitle(run.summary["name"])
    fig.tight_layout()
    return fig


def _points_alone(plt, run):
    points = run.bifurcation
    parameter, state = points.columns[0], points.columns[1]
    fig, ax = plt.subplots(figsize=(8, 5.5))
    ax.plot(points[parameter], points[state], ",k")
    ax.set_xlabel(parameter)
    ax.set_ylabel(state)
    fig.suptitle(run.summary["name"])
    fig.tight_layout()
    return fig


def _grid(plt, spectrum):
    import numpy
    from matplotlib.colors import TwoSlopeNorm

    first = spectrum.columns[0]
    second = spectrum.columns[1]
    # Many starts give a point several rows: its largest exponent.
    largest = spectrum.groupby([second, first])["lambda_1"].max().unstack(first)
    fig, ax = plt.subplots(figsize=(7, 5))
    # Chaos red, order blue, zero white where both are there.
    low, high = numpy.nanmin(largest.values), numpy.nanmax(largest.values)
    norm = TwoSlopeNorm(0.0, low, high) if low < 0 < high else None
    mesh = ax.pcolormesh(
        largest.columns, largest.index, largest.values, shading="nearest", cmap="RdBu_r", norm=norm
    )
    fig.colorbar(mesh, ax=ax, label="λ1 (largest)")
    ax.set_xlabel(first)
    ax.set_ylabel(second)
    fig.tight_layout()
    return fig


def _label(column: str) -> str:
    return "λ" + column.removeprefix("lambda_")
