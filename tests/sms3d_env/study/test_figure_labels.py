"""Labels drawn on the study's figures stay clear of what they label: the paper errors' dotted
lines on the sweep figure, the cell numbers on the success map (a reader must read both)."""

import numpy as np
import pytest

from sms3d_env.study import report, success_map
from sms3d_env.study.figures import boxes_overlap

# The committed docs/sweep_sensitivity_v1.png's successes (of 100) per variant and error.
SENSITIVITY = {"default": {0: 100, 20: 100, 30: 100, 40: 53, 60: 0},
               "loose_seal": {0: 100, 20: 100, 30: 100, 40: 99, 60: 20},
               "strong_root": {0: 100, 20: 100, 30: 100, 40: 53, 60: 0},
               "tight_seal": {0: 100, 20: 100, 30: 24, 40: 1, 60: 0},
               "weak_root": {0: 100, 20: 100, 30: 100, 40: 53, 60: 0}}
# The committed docs/sweep_map_v1_gantry.png's successes (of 100) per position error (mm) and orientation error.
MAP_ERRORS = (0, 5, 10, 20, 30, 40)
MAP = {0: (100, 100, 100, 100, 100, 53), 3: (100, 100, 100, 100, 94, 32),
       6: (100, 100, 100, 100, 63, 21), 12: (100, 100, 100, 64, 25, 7)}


def _row(variant, error, success, **extra):
    return {"variant": variant, "robot": "gantry", "source": "noisy", "error_deg": float(error), "reachable": True,
            "success": success, "failure_cause": None if success else "no_seal", **extra}


@pytest.fixture
def drawn(monkeypatch):
    """The figures the plotting functions would save, with a renderer of their final layout."""
    figures = []
    for module in (report, success_map):
        monkeypatch.setattr(module, "save_figure", lambda fig, path: figures.append(fig))
    yield figures
    import matplotlib.pyplot as plt

    for fig in figures:
        plt.close(fig)


def _extents(fig, texts):
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    return [t.get_window_extent(renderer) for t in texts]


def test_paper_error_labels_clear_their_dotted_lines_the_curves_and_the_legend(drawn, tmp_path):
    rows = [_row(v, e, k < wins) for v, by in SENSITIVITY.items() for e, wins in by.items() for k in range(100)]
    report.plot_sweep(rows, tmp_path / "sweep.png")
    (fig,) = drawn
    top = fig.axes[0]
    labels = [t for t in top.texts if "SMS3D" in t.get_text()]
    assert len(labels) == len(report.PAPER_ERRORS_DEG)
    boxes = _extents(fig, labels)
    vertical = [line for line in top.get_lines() if list(line.get_xdata()) == [line.get_xdata()[0]] * 2
                and line.get_linestyle() == ":"]
    xs = [top.transData.transform((line.get_xdata()[0], 0))[0] for line in vertical]
    assert len(xs) == len(report.PAPER_ERRORS_DEG)
    for box in boxes:
        assert not any(box.x0 - 1 <= x <= box.x1 + 1 for x in xs), "a dotted line crosses its label"
        assert not boxes_overlap(box, top.get_legend().get_window_extent(fig.canvas.get_renderer()))
        for line in top.get_lines():  # the curves: no marker or segment point inside a label
            if line in vertical:
                continue
            xy = top.transData.transform(line.get_xydata())
            inside = (xy[:, 0] > box.x0) & (xy[:, 0] < box.x1) & (xy[:, 1] > box.y0) & (xy[:, 1] < box.y1)
            assert not inside.any()
    assert not boxes_overlap(*boxes)


def test_success_map_iso_line_labels_clear_the_cell_numbers(drawn, tmp_path):
    rows = [_row("default", e, k < MAP[p][j], position_error_mm=float(p))
            for p in MAP for j, e in enumerate(MAP_ERRORS) for k in range(100)]
    rng = np.random.default_rng(0)
    rows += [_row("default", 0, True, source="perception", axis_error_deg=float(a), cap_top_error_mm=float(0.6 * a))
             for a in rng.gamma(2.0, 1.2, 100)]
    success_map.plot_map(rows, tmp_path / "map.png", "gantry, suction, 25 mushrooms")
    (fig,) = drawn
    ax = fig.axes[0]
    numbers = [t for t in ax.texts if "±" in t.get_text()]
    iso = [t for t in ax.texts if t.get_text().startswith("oracle")]
    assert len(numbers) == len(MAP) * len(MAP_ERRORS)
    assert sorted(t.get_text() for t in iso) == ["oracle − 10", "oracle − 2", "oracle − 5"]
    number_boxes, iso_boxes = _extents(fig, numbers), _extents(fig, iso)
    legend = ax.get_legend().get_window_extent(fig.canvas.get_renderer())
    frame = ax.get_window_extent(fig.canvas.get_renderer())
    for k, box in enumerate(iso_boxes):
        assert not any(boxes_overlap(box, number) for number in number_boxes), iso[k].get_text()
        assert not boxes_overlap(box, legend)
        assert not any(boxes_overlap(box, other) for other in iso_boxes[k + 1:])
        assert frame.x0 <= box.x0 and box.x1 <= frame.x1 and frame.y0 <= box.y0 and box.y1 <= frame.y1
