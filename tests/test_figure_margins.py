"""The figures laid out with fixed margins (pincal.figure_margins) keep every label inside the figure and
their panels apart: the HTML report's overview and parameter figures, and diagnose's plots, on labels as long
as pincal writes them and tick labels of seven characters."""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import matplotlib.pyplot as plt
import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg

from pincal.diagnosis import plots
from pincal.model.effects import Effect
from pincal.report import figures


def _laid_out(fig):
    """Each axes' extent with its tick labels, axis labels and title [px], and the figure's, after one draw."""
    renderer = FigureCanvasAgg(fig).get_renderer()
    fig.draw(renderer)
    return [ax.get_tightbbox(renderer) for ax in fig.axes], fig.bbox


def _assert_inside_and_apart(fig):
    boxes, page = _laid_out(fig)
    for box in boxes:  # 1 px: rounding of the canvas
        assert box.x0 >= -1 and box.y0 >= -1 and box.x1 <= page.x1 + 1 and box.y1 <= page.y1 + 1, (box, page)
    for i, first in enumerate(boxes):
        for second in boxes[i + 1:]:
            assert not first.overlaps(second), (first, second)


@pytest.fixture
def drawn(monkeypatch):
    """The figures the report and diagnose would write, kept instead of written."""
    kept = []
    monkeypatch.setattr(figures, "_svg_uri", lambda fig: kept.append(fig) or "")
    monkeypatch.setattr(plots, "_save", lambda fig, path: kept.append(fig))
    return kept


@pytest.mark.parametrize("spread", [1.0, 300.0], ids=["linear", "log"])
def test_the_overview_keeps_its_labels_inside(drawn, spread):
    models = [("nominal geometry", 3.956 * spread, 0.2), ("calibrated geometry", 2.404, 0.0800),
              ("geometry and effects", 1.729, 0.0213)]
    figures.overview_figure([{"set": "calibration", "models": models}, {"set": "held-out", "models": models}])
    _assert_inside_and_apart(drawn[0])


def test_the_parameter_figure_keeps_its_labels_inside_and_its_panels_apart(drawn):
    rows = [{"name": f"{joint}.{axis}", "change": change, "std": 0.3, "unit": unit}
            for joint, change in (("wrist_ft_tool_link_joint", -0.00125), ("arm_1_joint", 44.2))
            for axis, unit in (("tx", "mm"), ("rx", "mrad"), ("scale", "%"))]
    figures.parameter_figure(rows)
    assert len(drawn[0].axes) == 3
    _assert_inside_and_apart(drawn[0])


@pytest.mark.parametrize("shift", [1e-6, 0.03], ids=["seven-character ticks", "tens of mrad"])
def test_the_diagnose_plots_keep_their_labels_inside(drawn, tmp_path, shift):
    rng = np.random.default_rng(3)
    driver = rng.uniform(-40.0, 55.0, 30)
    step = SimpleNamespace(driver=driver, joint_residual=-shift * driver / 40.0, fitted_shift=-shift * driver / 40.0,
                           effect=Effect("compliance", "wrist_ft_tool_link_joint"), shift_unit="rad",
                           driver_label="gravity torque tau_j [N·m]", delta_bic=-8447.3)
    errors = SimpleNamespace(position_m=rng.uniform(0.0, 0.004, (400, 4)), position=SimpleNamespace(rms=2.404))
    diagnosis = SimpleNamespace(steps=[SimpleNamespace(**vars(step), calibration_before=errors, heldout_before=errors)],
                                calibration_errors=errors, heldout_errors=errors)
    plots.plot_diagnosis(diagnosis, tmp_path)
    assert len(drawn) == 2
    for fig in drawn:
        _assert_inside_and_apart(fig)


@pytest.fixture(scope="module")
def study():
    """A study small enough for half a second whose summary draws every figure (no noise limit: its tasks take
    ~1 s each)."""
    from pincal.study.protocol import StudyConfig
    from pincal.study.run import run_study

    return run_study(StudyConfig(deviations=("large",), levels=2, repeats=1, restarts=0, limit_pose_sets=0),
                     workers=1)


def _scaled(result, factor):
    """``result`` with every error of its summary (the y values of the figures) times ``factor``."""
    summary = [{key: value * factor if key.startswith(("pos_", "rot_")) else value for key, value in row.items()}
               for row in result.summary]
    return dataclasses.replace(result, summary=summary)


# Every study figure is laid out by one function (pincal.study.figures._fix_margins); these cover what it sizes,
# at ~0.4 s a figure: two-line titles (figure 2), the gap between rows (figure 5's 2 × 2 grid), titles wider than
# their panels and, scaled to micrometres, tick labels of seven characters (figure 6: 0.00025 mm).
@pytest.mark.parametrize("name, factor", [("figure2", 1.0), ("figure5", 1.0), ("figure6", 4e-3)],
                         ids=["two-line titles", "two rows", "wide titles, seven-character ticks"])
def test_the_study_figures_keep_their_labels_inside_and_their_panels_apart(study, monkeypatch, tmp_path, name,
                                                                           factor):
    from pincal.study import figures as study_figures

    kept = []
    monkeypatch.setattr(study_figures, "_save", lambda fig, path: study_figures._fix_margins(fig) or kept.append(fig))
    getattr(study_figures, name)(_scaled(study, factor), tmp_path / name)
    labels = [label.get_text() for ax in kept[0].axes for label in ax.get_yticklabels()]
    if factor < 1.0:
        assert max(len(label) for label in labels) >= 7, labels
    _assert_inside_and_apart(kept[0])
    plt.close(kept[0])  # drawn through pyplot: its figure manager keeps it open otherwise
