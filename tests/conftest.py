"""Shared fixtures: the packaged KUKA LWR 4+ and simulated experiments (seeded)."""

from __future__ import annotations

import numpy as np
import pytest

from pincal.model.chain import KinematicChain
from pincal.model.dh import KUKA_LWR4_DH, TABLE2_LARGE
from pincal.robots import KUKA_FLANGE_LINK, kuka_lwr4plus_urdf
from pincal.simulation.cells import INDUSTRIAL_6R_START, INDUSTRIAL_6R_TABLE
from pincal.simulation.paper import SimulationSettings, simulate_experiment


@pytest.fixture(scope="session")
def kuka_urdf():
    return kuka_lwr4plus_urdf()


@pytest.fixture
def kuka_chain(kuka_urdf):
    return KinematicChain.from_urdf(kuka_urdf, KUKA_FLANGE_LINK)


@pytest.fixture(scope="session")
def noisy_large_experiment(kuka_urdf):
    chain = KinematicChain.from_urdf(kuka_urdf, KUKA_FLANGE_LINK)
    settings = SimulationSettings(sigma_pos_mm=0.055, sigma_rot_deg=0.055, seed=3)
    return simulate_experiment(chain, KUKA_LWR4_DH, TABLE2_LARGE, settings)


def assert_close(actual, expected, atol, what=""):
    """Assert arrays are close and free of NaN (NaN never passes)."""
    actual = np.asarray(actual, dtype=float)
    expected = np.asarray(expected, dtype=float)
    assert actual.shape == expected.shape, f"{what}: shape {actual.shape} != {expected.shape}"
    assert np.all(np.isfinite(actual)), f"{what}: non-finite values"
    err = np.abs(actual - expected).max() if actual.size else 0.0
    assert err <= atol, f"{what}: max abs error {err:.3g} > {atol:.3g}"


def numeric_jacobian(fun, x, step=1e-6):
    """Central finite differences of ``fun`` at ``x``: columns stacked on the last axis."""
    columns = []
    for i in range(x.size):
        dx = np.zeros_like(x)
        dx[i] = step
        columns.append((fun(x + dx) - fun(x - dx)) / (2 * step))
    return np.stack(columns, axis=-1)


INDUSTRIAL_ARM_TABLE = INDUSTRIAL_6R_TABLE  # the unseen-setup tests' arm (pincal.simulation.cells)
INDUSTRIAL_ARM_START = INDUSTRIAL_6R_START


@pytest.fixture(scope="session")
def industrial_arm_urdf(tmp_path_factory):
    from pincal.model.urdf_from_dh import urdf_from_dh_table

    folder = tmp_path_factory.mktemp("industrial_arm")
    (folder / "arm.csv").write_text(INDUSTRIAL_ARM_TABLE, encoding="utf-8")
    urdf_from_dh_table(folder / "arm.csv", "modified", folder / "arm.urdf", degrees=True)
    return folder / "arm.urdf"
