"""Held-out evaluation of the shipped weights and the error-vs-angle plots."""

from __future__ import annotations

import json

import numpy as np
import pytest

from perception.baselines.point_transformer import eval_heldout
from perception.plots.error_plots import binned_means, plot_errors


def test_binned_means_are_equal_count_bin_means() -> None:
    x = np.arange(16.0)
    y = 2 * x + 1
    centres, means = binned_means(x, y, bins=4)
    np.testing.assert_allclose(centres, [1.5, 5.5, 9.5, 13.5])
    np.testing.assert_allclose(means, 2 * centres + 1)


def test_plot_errors_writes_both_figures(tmp_path) -> None:
    rng = np.random.default_rng(0)
    meta = [{"roll": r, "pitch": p, "yaw": y, "cap_diameter": d}
            for r, p, y, d in zip(*rng.normal(0, 0.3, (2, 40)), rng.uniform(0, 6, 40), rng.uniform(0.02, 0.08, 40), strict=True)]  # fmt: skip
    paths = plot_errors({"stem axis": rng.uniform(0, 5, 40)}, meta, tmp_path / "figs", "test")
    assert [p.name for p in paths] == ["error_vs_angles.png", "error_vs_size.png"]
    assert all(p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" for p in paths)


def test_heldout_cli_scores_the_shipped_weights(tmp_path, capsys) -> None:
    out = tmp_path / "heldout.json"
    assert eval_heldout.main(["--num", "40", "--views", "2", "--json", str(out), "--plots", str(tmp_path / "plots")]) == 0
    results = json.loads(out.read_text())["results"]
    train, unseen = results.values()
    assert train["n"] == unseen["n"] == 40
    # The shipped network is far better than the "always upright" prior (≈ 25° on these views).
    assert train["mean_axis_deg"] < 6.0 < train["upright_prior_mean_axis_deg"]
    assert unseen["mean_axis_deg"] < 8.0
    assert sum(b["n"] for b in train["by_tilt_to_camera_deg"].values()) == 40
    assert (tmp_path / "plots" / "error_vs_angles.png").exists()
    assert "wrote" in capsys.readouterr().out


def test_plots_without_synthetic_views_is_refused(tmp_path, capsys) -> None:
    with pytest.raises(SystemExit):
        eval_heldout.main(["--no-synthetic", "--plots", str(tmp_path)])
    assert "drop --no-synthetic" in capsys.readouterr().err


def test_estimate_errors_are_zero_for_the_truth() -> None:
    class Oracle:
        def estimate_batch(self, clouds):
            return [type("E", (), {"rotation": r})() for r in truth[: len(clouds)]]

    from perception.baselines.point_transformer.data import PointCloudSample

    truth = [np.eye(3), np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])]
    samples = [PointCloudSample(np.zeros((20, 3), np.float32), r.astype(np.float32)) for r in truth]
    err = eval_heldout.estimate_errors(Oracle(), samples)
    assert err["geodesic"] == pytest.approx([0, 0], abs=1e-4) and err["axis"] == pytest.approx([0, 0], abs=1e-4)
    assert err["upright"] == pytest.approx([180.0, 90.0])  # stem +z points away from the camera; then sideways
