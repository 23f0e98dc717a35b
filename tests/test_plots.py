"""Figure 9's event labels: never on top of each other, never outside the axes
(tssac_core.reporting.plots.place_labels)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from tssac_core.reporting.plots import place_labels  # noqa: E402


def test_clustered_event_labels_do_not_overlap():
    fig, ax = plt.subplots(figsize=(6.5, 6.5))
    ax.set_xlim(0, 100)
    ax.set_ylim(0, 100)
    # A mission's usual cluster (radar on, identified, hit, within a few km near the SAM), plus a corner event.
    events = [
        ("radar on", 64.0, 62.0),
        ("identified", 65.0, 63.0),
        ("hit", 66.0, 63.5),
        ("hazard (strike)", 65.5, 62.5),
        ("left area (decoy)", 99.5, 99.5),
        ("hazard (detect)", 64.5, 62.8),
    ]
    fig.tight_layout()
    texts = place_labels(ax, events)
    renderer = fig.canvas.get_renderer()
    boxes = [t.get_window_extent(renderer) for t in texts]
    frame = ax.get_window_extent(renderer)
    assert [t.get_text() for t in texts] == [e[0] for e in events]
    for i, a in enumerate(boxes):
        assert frame.x0 <= a.x0 and a.x1 <= frame.x1 and frame.y0 <= a.y0 and a.y1 <= frame.y1, texts[i].get_text()
        for j in range(i):
            assert not a.overlaps(boxes[j]), (texts[i].get_text(), texts[j].get_text())
    plt.close(fig)


def test_the_old_fixed_offset_would_overlap():
    """The same cluster with every label at (4, 4) points, as before: the test above would fail on it."""
    fig, ax = plt.subplots(figsize=(6.5, 6.5))
    ax.set_xlim(0, 100)
    ax.set_ylim(0, 100)
    texts = [
        ax.annotate(label, (x, y), xytext=(4, 4), textcoords="offset points", fontsize=7.5)
        for label, x, y in [("radar on", 64.0, 62.0), ("identified", 65.0, 63.0)]
    ]
    renderer = fig.canvas.get_renderer()
    a, b = (t.get_window_extent(renderer) for t in texts)
    assert a.overlaps(b)
    plt.close(fig)
