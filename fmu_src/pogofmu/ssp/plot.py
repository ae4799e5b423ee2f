"""The run's figure: every signal against time, drawn from the recorder's min/max envelope."""
from __future__ import annotations

from pathlib import Path

MAX_PANELS = 16  # signals drawn at most (a system of hundreds of components: the first ones; the CSV has all)


def plotted(names, types, connections):
    """The signals the figure draws (at most MAX_PANELS): ``names`` are the recorded columns."""
    rec = type("Columns", (), {"names": ["time"] + list(names), "types": types})()
    return _panels(rec, connections)[0]


def _panels(rec, connections):
    """The figure's panels, one signal each (integer signals last); a connected input is not
    drawn again (it is its source's copy, held over the step): ``copies`` names it instead."""
    fed = {f"{c.end_element}.{c.end_connector}": f"{c.start_element}.{c.start_connector}" for c in connections}
    copies = {}
    for dst, src in fed.items():
        copies.setdefault(src, []).append(dst)
    shown = [n for n in rec.names[1:] if n not in fed and n != "event" and not n.endswith(".n_events")]
    shown = sorted(shown, key=lambda n: rec.types[n] != "Real")  # integer signals last
    rec_total = len(shown)
    return shown[:MAX_PANELS], copies, rec_total


def figure(rec, title: str, connections=()):
    """The run's figure (a matplotlib Figure): every signal against time, y-labels with units,
    integer ticks for the integer signals, each connected signal drawn once (its inputs named in
    the label), drawn from the run's min/max envelope."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    env = rec.envelope()
    col = {n: i for i, n in enumerate(rec.names)}
    panels, copies, total = _panels(rec, connections)
    fig, axes = plt.subplots(len(panels), 1, figsize=(9, 1.7 * len(panels) + 0.9), sharex=True, squeeze=False)
    for ax, name in zip(axes[:, 0], panels):
        t, v = env.series(col[name])
        label = " = ".join([name] + copies.get(name, []))
        if rec.types[name] != "Real":
            ax.step(t, v, where="post", lw=0.8, label=label)
            ax.yaxis.set_major_locator(MaxNLocator(integer=True))
        else:
            ax.plot(t, v, lw=0.8, label=label)
        ax.set_ylabel(f"{name.split('.', 1)[1]} [{rec.units.get(name) or '-'}]")
        ax.legend(loc="upper right", fontsize=7, handlelength=1)
        ax.grid(True, alpha=0.3)
    axes[-1, 0].set_xlabel("time [s]")
    fig.suptitle(title if len(panels) == total else
                 f"{title}\n(the first {len(panels)} of {total} signals; the CSV has every column)", fontsize=10)
    fig.align_ylabels(axes[:, 0])
    fig.tight_layout()
    return fig


def plot(rec, path: Path, title: str, connections=()):
    """:func:`figure` written to ``path`` (PNG)."""
    import matplotlib.pyplot as plt

    fig = figure(rec, title, connections)
    try:
        fig.savefig(path, dpi=110)
    finally:
        plt.close(fig)
    return path
