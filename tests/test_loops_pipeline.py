"""Loop closure through the pipeline, the results folder, g2o export/import and the relation clock."""

from __future__ import annotations

import gzip

import numpy as np
import pytest
from conftest import ScanList, run_cli, shared_file
from test_loops import _block_loop_world, _loop_path, _scans

from dynslam2d.config import Config, with_overrides
from dynslam2d.errors import DynSlamError
from dynslam2d.io.g2o import format_g2o, read_g2o, write_g2o
from dynslam2d.io.relclock import read_clock_pairs
from dynslam2d.pipeline import render_map, run
from dynslam2d.slam.posegraph import PoseGraph, diag_info
from dynslam2d.types import SourceMeta


@pytest.fixture(scope="module")
def loop_runs() -> tuple:
    gt = _loop_path(step=0.2, laps=1.3)
    scans = _scans(_block_loop_world(), gt, seed=1)
    meta = SourceMeta(format="sim", origin="test:block-loop", count=len(scans), beams=360)
    on = run(ScanList(scans, meta), Config())
    off = run(ScanList(scans, meta), with_overrides(Config(), {"loop": {"enabled": False}}))
    return gt, on, off


def test_loop_closure_off_is_the_front_end_and_on_keeps_it(loop_runs: tuple) -> None:
    gt, on, off = loop_runs
    assert off.loop is None and off.frontend_trajectory is None
    front = on.frontend_trajectory if on.frontend_trajectory is not None else on.trajectory
    # the loop closure never touches the front end: its trajectory is bit for bit the one of 'off'
    assert np.array_equal(front.poses, off.trajectory.poses)
    assert on.loop is not None and on.loop.stats["loops_active"] >= 3
    s = on.summary()["loop_closure"]
    assert s["enabled"] and s["loops_active"] == on.loop.stats["loops_active"]
    # every loop closer counter reaches summary.json, the far searches skipped by the place cap among them
    for key in ("searches", "far_searches", "far_skipped", "far_candidates", "far_loops"):
        assert s[key] == on.loop.stats[key], key
    # the simulated front end hardly drifts: the loops agree with it, the result is no worse
    def ate(poses: np.ndarray) -> float:
        return float(np.sqrt(np.mean(np.sum((poses[:, :2] - (gt[:, :2] - gt[0, :2])) ** 2, axis=1))))

    # the map frame is the first laser pose (heading 0 at gt[0]), so positions compare directly
    assert ate(on.trajectory.poses) <= ate(off.trajectory.poses) + 0.005


def test_map_rendered_at_front_end_poses_is_the_online_map(loop_runs: tuple) -> None:
    """Re-rendering integrates the same kept beams in the same order: at the front end's poses it
    gives back the online map exactly (removed beams stay out the same way)."""
    _gt, on, off = loop_runs
    loop = on.loop
    saved = loop.node_poses
    try:
        loop.node_poses = loop.frontend[loop.keyframe_scans]
        grid, lo = render_map(loop, on.config.slam)
    finally:
        loop.node_poses = saved
    np.testing.assert_array_equal(lo, off.logodds)
    assert grid.shape == off.grid.shape


def test_g2o_write_read_round_trip(tmp_path, loop_runs: tuple) -> None:
    _gt, on, _off = loop_runs
    g = on.loop.graph
    path = write_g2o(tmp_path / "graph.g2o", g)
    back = read_g2o(path)
    active = [e for e in g.edges if e.active]
    assert back.poses.shape == (g.n_nodes, 3) and back.edges.shape == (len(active), 2)
    np.testing.assert_allclose(back.poses, g.poses, atol=1e-6)
    np.testing.assert_allclose(back.z, np.array([e.z for e in active]), atol=1e-6)
    np.testing.assert_allclose(back.info, np.array([e.info for e in active]), rtol=1e-5)
    assert back.loop.sum() == sum(e.loop for e in active) > 0 and back.fixed == [0]
    # the graph read back optimises to the same poses (it is already at its optimum)
    g2 = back.to_posegraph()
    g2.optimise("none", outlier_chi2=None)
    assert np.abs(g2.poses[:, :2] - g.poses[:, :2]).max() < 0.01


def test_g2o_format_and_errors(tmp_path) -> None:
    g = PoseGraph()
    a, b = g.add_node((0, 0, 0)), g.add_node((1, 0, 0.5))
    g.add_edge(a, b, (1.0, 0.0, 0.5), diag_info(0.1, 0.01), loop=True)
    text = format_g2o(g)
    assert "VERTEX_SE2 1 1.000000 0.000000 0.500000" in text
    # information upper triangle row by row: I11 I12 I13 I22 I23 I33
    assert "EDGE_SE2 0 1 1.000000 0.000000 0.500000 100 0 0 100 0 10000" in text
    bad = tmp_path / "bad.g2o"
    bad.write_text("VERTEX_SE2 0 0 0 0\nEDGE_SE2 0 7 1 0 0 1 0 0 1 0 1\n")
    with pytest.raises(DynSlamError, match="vertex that is not in the file"):
        read_g2o(bad)
    bad.write_text("VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1\n")
    with pytest.raises(DynSlamError, match=r"bad.g2o:1"):
        read_g2o(bad)


def test_clock_pairs_interpolate_the_offset(tmp_path) -> None:
    log = tmp_path / "both.log.gz"
    n = 181
    ranges = " ".join(["1.0"] * n)
    lines = []
    for logger, ipc in ((10.0, 1210.0), (20.0, 1221.0)):  # offset drifts from 1200 to 1201 s
        lines.append(f"FLASER {n} {ranges} 0 0 0 0 0 0 {ipc} host {logger}")
    with gzip.open(log, "wt") as fh:
        fh.write("\n".join(lines) + "\n")
    cm = read_clock_pairs(log)
    np.testing.assert_allclose(cm.to_ipc(np.array([5.0, 10.0, 15.0, 20.0, 30.0])),
                               [1205.0, 1210.0, 1215.5, 1221.0, 1231.0])
    same = tmp_path / "same.log"
    same.write_text(f"FLASER {n} {ranges} 0 0 0 0 0 0 5.0 host 5.0\n")
    with pytest.raises(DynSlamError, match="cannot map the clocks"):
        read_clock_pairs(same)


@pytest.mark.shared_data
def test_fr079_relations_resolve_through_the_flirtlib_clock() -> None:
    """fr079's corrected log has logger time only; the FLIRTLib copy maps it to the relations' ipc
    time: 1628 of 1685 relations find a scan within 0.1 s at both ends (data README)."""
    from dynslam2d.io.carmen import CarmenSource
    from dynslam2d.io.relations import match_relation_stamps, read_relations

    stamps = np.array([s.stamp for s in CarmenSource(shared_file("fr079/freiburg-079-corrected.log.gz"))])
    cm = read_clock_pairs(shared_file("fr079/fr079.flirtlib.log"))
    rel = read_relations(shared_file("fr079/fr079.relations"))
    _i1, _i2, ok = match_relation_stamps(rel, cm.to_ipc(stamps), tol=0.1)
    assert int(ok.sum()) == 1628
    # without the mapping (logger time as is) nothing matches
    assert not match_relation_stamps(rel, stamps, tol=0.1)[2].any()


def test_cli_loop_closure_outputs(tmp_path, capsys) -> None:
    out_on = tmp_path / "on"
    code, _o, err = run_cli(capsys, "run", "sim:paper", "--duration", "4", "--out", str(out_on), "-q")
    assert code == 0, err
    assert (out_on / "graph.g2o").exists() and (out_on / "trajectory_frontend.tum").exists()
    read_g2o(out_on / "graph.g2o")
    out_off = tmp_path / "off"
    code, _o, err = run_cli(capsys, "run", "sim:paper", "--duration", "4", "--out", str(out_off), "-q",
                            "--loop-closure", "off")
    assert code == 0, err
    assert not (out_off / "graph.g2o").exists() and not (out_off / "trajectory_frontend.tum").exists()
    assert (out_off / "trajectory.tum").read_text() == (out_on / "trajectory.tum").read_text()
    code, _o, err = run_cli(capsys, "run", "sim:paper", "--out", str(tmp_path / "x"), "--loop-closure", "maybe")
    assert code != 0 and "--loop-closure must be 'on' or 'off'" in err


@pytest.mark.shared_data
def test_csail_false_loops_change_the_relations_by_less_than_5mm() -> None:
    """MIT CSAIL, laser only, loop closure on: a tenth of the accepted loops replaced by wrong ones
    (1–3 m, 0.3 rad off) changes the Kümmerle relation error by less than 5 mm."""
    from dynslam2d.eval.relations import relation_errors_from
    from dynslam2d.io.carmen import CarmenSource
    from dynslam2d.io.relations import read_relations
    from dynslam2d.io.trajectory import Trajectory
    from dynslam2d.slam.loops import scan_poses
    from dynslam2d.slam.posegraph import PoseGraph

    source = CarmenSource(shared_file("mit-csail/mit-csail.clf"))
    res = run(source, Config())
    rel = read_relations(shared_file("mit-csail/mit-csail.relations"))
    loop = res.loop
    good = [e for e in loop.graph.edges if e.loop and e.active]
    assert len(good) >= 50
    node_front = loop.frontend[loop.keyframe_scans]
    scan_node = np.searchsorted(loop.keyframe_scans, np.arange(len(loop.frontend)), side="right") - 1
    cfg = res.config.loop
    rng = np.random.default_rng(12)

    def relations_with(bad: set[int]) -> float:
        g = PoseGraph()
        for p in node_front:
            g.add_node(p)
        for e in loop.graph.edges:
            if not e.loop:
                g.add_edge(e.i, e.j, e.z, e.info)
        for k, e in enumerate(good):
            z = e.z + (np.array([rng.uniform(1, 3) * rng.choice([-1, 1]), rng.uniform(1, 3), 0.3]) if k in bad else 0)
            g.add_edge(e.i, e.j, z, e.info, loop=True)
        g.optimise(cfg.kernel, cfg.kernel_scale, cfg.iterations, cfg.outlier_chi2)
        poses = scan_poses(loop.frontend, scan_node, node_front, g.poses)
        return relation_errors_from(Trajectory(res.trajectory.stamps, poses), rel).trans_mean

    clean = relations_with(set())
    corrupted = relations_with(set(rng.choice(len(good), size=len(good) // 10, replace=False).tolist()))
    assert abs(corrupted - clean) < 0.005
    assert clean < 0.035


def test_frame_base_link_rewrites_the_front_end_trajectory_too(tmp_path, capsys) -> None:
    from dynslam2d.io.trajectory import read_tum

    out = tmp_path / "base"
    code, _o, err = run_cli(capsys, "run", "sim:static", "--duration", "1", "--out", str(out), "--frame", "base_link",
                            "-q")
    assert code == 0, err
    base = read_tum(out / "trajectory.tum")
    front = read_tum(out / "trajectory_frontend.tum")
    # no loop on a 1 s run: the front end's trajectory is the trajectory, in the same (base_link) frame
    np.testing.assert_allclose(front.poses, base.poses, atol=1e-9)
    assert np.hypot(*base.poses[0, :2]) == pytest.approx(0.15)
