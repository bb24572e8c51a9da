"""The figures laid out with fixed margins (pincal.figure_margins) keep every label inside the figure and
their panels apart: the HTML report's overview and parameter figures, and diagnose's plots, on labels as long
as pincal writes them and tick labels of seven characters."""

from __future__ import annotations

from types import SimpleNamespace

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
