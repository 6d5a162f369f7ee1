"""dynslam2d batch: jobs × settings, one results folder each, resume, failures, order, Ray."""

from __future__ import annotations

import csv
import io
import json
import shutil
import sys
from pathlib import Path

import pytest

from dynslam2d.batch import make_jobs, parse_setting, run_batch
from dynslam2d.batch.engine import RAY_HINT, map_jobs
from dynslam2d.batch.runs import is_timing_column
from dynslam2d.errors import DynSlamError

INPUTS = ["sim:paper-1", "sim:static"]
OPTIONS = {"duration": 2.0}


def _jobs(inputs: list[str] = INPUTS):
    return make_jobs(inputs, [parse_setting("filter.mode=none,box")], options=OPTIONS)


def _rows(path: Path) -> list[dict[str, str]]:
    return list(csv.DictReader(io.StringIO(path.read_text())))


def _reproducible(rows: list[dict[str, str]]) -> list[dict[str, str]]:
    return [{k: v for k, v in r.items() if not is_timing_column(k)} for r in rows]


@pytest.fixture(scope="module")
def serial_batch(tmp_path_factory):
    out = tmp_path_factory.mktemp("batch") / "b"
    seen: list[str] = []
    result = run_batch(_jobs(), out, workers=1, on_outcome=lambda o: seen.append(f"{o.name}:{o.status}"))
    return out, result, seen


def test_job_names_and_order_are_deterministic_and_readable():
    jobs = make_jobs(["sim:paper-1", "/data/a/parallel.bag", "/data/b/parallel.bag"],
                     [parse_setting("filter.mode=none,box"), parse_setting("slam.map_resolution=0.05,0.025")])
    names = [j.name for j in jobs]
    assert names[:4] == ["sim-paper-1__filter.mode=none__slam.map_resolution=0.05",
                         "sim-paper-1__filter.mode=none__slam.map_resolution=0.025",
                         "sim-paper-1__filter.mode=box__slam.map_resolution=0.05",
                         "sim-paper-1__filter.mode=box__slam.map_resolution=0.025"]
    assert names[4].startswith("a-parallel__") and names[8].startswith("b-parallel__")
    assert len(set(names)) == 12
    assert jobs[1].config["slam"]["map_resolution"] == 0.025 and jobs[2].config["filter"]["mode"] == "box"


@pytest.mark.parametrize("spec, words", [
    ("filter.mod=none", "no key 'mod'"), ("filter=none", "is a section"), ("filter.mode", "KEY=VALUE"),
    ("slam.map_resolution=0.05,,0.1", "empty value"),
])
def test_bad_settings_name_the_option(spec, words):
    with pytest.raises(DynSlamError, match="--set") as exc:
        parse_setting(spec)
    assert words in str(exc.value)


def test_bad_value_fails_before_any_run():
    with pytest.raises(DynSlamError, match="--set slam.map_resolution=abc"):
        make_jobs(["sim:paper-1"], [parse_setting("slam.map_resolution=abc")])


def test_batch_two_inputs_by_two_settings(serial_batch):
    out, result, seen = serial_batch
    names = [j.name for j in _jobs()]
    assert [o.status for o in result.outcomes] == ["done"] * 4 and len(seen) == 4
    rows = _rows(out / "batch.csv")
    assert [r["run"] for r in rows] == names
    assert [r["filter.mode"] for r in rows] == ["none", "box", "none", "box"]
    for name, r in zip(names, rows):
        marker = json.loads((out / name / "run.json").read_text())
        assert marker["status"] == "complete"
        summary = json.loads((out / name / "summary.json").read_text())
        metrics = json.loads((out / name / "metrics.json").read_text())
        assert int(r["summary.scans"]) == summary["scans"] == 40
        assert float(r["metrics.ate_rmse_m"]) == metrics["ate_rmse_m"]
        assert float(r["metrics.map.iou"]) == metrics["map"]["iou"]
        assert r["summary.filter"] == r["filter.mode"]
    # the filter setting reached the runs: the moving boxes of paper-1 are removed only with "box"
    assert float(rows[0]["summary.removed_beam_share"]) == 0.0
    assert float(rows[1]["summary.removed_beam_share"]) > 0.02
    md = (out / "batch.md").read_text()
    assert all(f"| {n} |" in md for n in names) and "metrics.map.weighted_rmse" in md
    record = json.loads((out / "batch.json").read_text())
    assert record["status"] == "complete" and [r["name"] for r in record["runs"]] == names


def test_resume_skips_finished_runs_and_reruns_an_incomplete_one(serial_batch, tmp_path):
    out = tmp_path / "copy"
    shutil.copytree(serial_batch[0], out)  # the fixture's folder stays as the serial run left it
    names = [j.name for j in _jobs()]
    mtimes = {n: (out / n / "run.json").stat().st_mtime_ns for n in names}
    before = _rows(out / "batch.csv")
    # the third run was interrupted: its marker says incomplete
    marker = out / names[2] / "run.json"
    data = json.loads(marker.read_text())
    marker.write_text(json.dumps({**data, "status": "incomplete"}))
    ran: list[str] = []
    again = run_batch(_jobs(), out, workers=1, on_outcome=lambda o: ran.append(o.status))
    assert [o.status for o in again.outcomes] == ["skipped", "skipped", "done", "skipped"]
    assert sorted(ran) == ["done", "skipped", "skipped", "skipped"]
    for i, n in enumerate(names):
        changed = (out / n / "run.json").stat().st_mtime_ns != mtimes[n]
        assert changed == (i == 2)
    # a job whose options changed since its folder was written is run again, not skipped
    jobs = _jobs()
    jobs[3].options = {**jobs[3].options, "skip_bad": True}
    third = run_batch(jobs, out, workers=1)
    assert [o.status for o in third.outcomes] == ["skipped", "skipped", "skipped", "done"]
    run_batch(_jobs(), out, workers=1)  # back to the original job: runs once more
    after = _rows(out / "batch.csv")
    assert [r["status"] for r in after] == ["skipped", "skipped", "skipped", "done"]
    assert _reproducible([{**r, "status": ""} for r in after]) == _reproducible([{**r, "status": ""} for r in before])


def test_failing_input_is_recorded_and_the_others_finish(tmp_path):
    bad = tmp_path / "broken.bag"
    bad.write_bytes(b"#ROSBAG V2.0\n" + b"\x00" * 64)
    jobs = make_jobs([str(bad), "sim:static"], [], options={"duration": 1.0})
    out = tmp_path / "b"
    result = run_batch(jobs, out, workers=1)
    assert [o.status for o in result.outcomes] == ["failed", "done"]
    err = result.outcomes[0].error
    assert err and "\n" not in err and "broken.bag" in err
    rows = _rows(out / "batch.csv")
    assert rows[0]["status"] == "failed" and rows[0]["error"] == err
    assert rows[1]["status"] == "done" and int(rows[1]["summary.scans"]) == 20
    assert not (out / jobs[0].name).exists()  # nothing half-written is left
    assert json.loads((out / jobs[1].name / "run.json").read_text())["status"] == "complete"


def test_foreign_folder_is_refused(tmp_path):
    (tmp_path / "mine.txt").write_text("user data")
    with pytest.raises(DynSlamError, match="not a dynslam2d batch folder"):
        run_batch(_jobs(["sim:static"]), tmp_path)
    assert [p.name for p in tmp_path.iterdir()] == ["mine.txt"]


def test_process_pool_gives_the_serial_batch_csv(serial_batch, tmp_path):
    out, _, _ = serial_batch
    seen: list[str] = []
    jobs = _jobs(["sim:paper-1"])  # the serial batch's first two runs
    pooled = run_batch(jobs, tmp_path / "p", workers=2, on_outcome=lambda o: seen.append(o.name))
    assert [o.status for o in pooled.outcomes] == ["done"] * 2
    assert sorted(seen) == sorted(j.name for j in jobs)
    assert _reproducible(_rows(tmp_path / "p" / "batch.csv")) == _reproducible(_rows(out / "batch.csv")[:2])


def _square(x: int) -> int:
    if x == 3:
        raise ValueError("three\nis bad")
    return x * x


def test_engine_keeps_job_order_and_records_errors_in_one_line():
    outs = map_jobs(_square, [1, 2, 3, 4], workers=2)
    assert [o.value for o in outs] == [1, 4, None, 16]
    assert [o.status for o in outs] == ["done", "done", "failed", "done"]
    assert outs[2].error == "ValueError: three is bad"


def test_ray_missing_gives_the_install_hint(monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray now raises ImportError
    with pytest.raises(DynSlamError) as exc:
        map_jobs(_square, [1], ray="auto")
    assert str(exc.value) == RAY_HINT and "dynslam2d[cluster]" in RAY_HINT


def test_batch_cli_exit_code_progress_and_tables(tmp_path):
    from typer.testing import CliRunner

    from dynslam2d.cli import app

    bad = tmp_path / "broken.clf"
    bad.write_text("FLASER 3 1.0 1.0\n")
    out = tmp_path / "b"
    res = CliRunner().invoke(app, ["batch", str(bad), "sim:static", "--duration", "1", "--out", str(out),
                                   "--set", "filter.mode=none", "--workers", "1"])
    assert res.exit_code == 1, res.output
    rows = _rows(out / "batch.csv")
    assert [r["status"] for r in rows] == ["failed", "done"]
    assert "broken__filter.mode=none" in res.output and "failed" in res.output


def test_batch_on_ray_gives_identical_metrics(serial_batch, tmp_path):
    ray = pytest.importorskip("ray", reason="Ray is not installed (the optional extra: pip install "
                                            "'dynslam2d[cluster]')")
    out, _, _ = serial_batch
    started = not ray.is_initialized()
    if started:
        ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        on_ray = run_batch(_jobs(["sim:paper-1"]), tmp_path / "r", ray="auto")
    finally:
        if started:
            ray.shutdown()
    assert [o.status for o in on_ray.outcomes] == ["done"] * 2
    rows = _rows(tmp_path / "r" / "batch.csv")
    assert float(rows[1]["summary.removed_beam_share"]) > 0.02  # real runs, not empty rows
    assert _reproducible(rows) == _reproducible(_rows(out / "batch.csv")[:2])


def test_experiment_cells_run_through_the_engine_with_identical_rows():
    from dynslam2d.experiments import run_experiment

    def table(result):
        return [{k: "nan" if v != v else v for k, v in r.items() if k != "scans_per_s"} for r in result.rows]

    done: list[str] = []
    serial = run_experiment(("paper-1",), ("none", "box"), duration=2.0, progress=done.append)
    pooled = run_experiment(("paper-1",), ("none", "box"), duration=2.0, workers=2)
    assert done == ["paper-1 / none", "paper-1 / box"]
    assert table(pooled) == table(serial)
    assert [(r["trial"], r["config"]) for r in pooled.rows] == [("paper-1", "none"), ("paper-1", "box")]
    assert serial.rows[0]["removal_recall"] == 0.0 and serial.rows[1]["removal_recall"] > 0.2
    import numpy as np

    a, b = pooled.maps[("paper-1", "box")], serial.maps[("paper-1", "box")]
    assert a.origin == b.origin and np.array_equal(a.prob, b.prob, equal_nan=True)


def test_timing_columns_are_the_machine_dependent_ones():
    timing = ("seconds", "summary.wall_time_s", "summary.loop_closure.total_ms", "summary.loop_closure.search_ms",
              "summary.kernel_compile_s", "summary.steady_scans_per_s", "summary.stage_ms_median.match",
              "summary.first_scan_ms", "metrics.cleanup.pass_time_s")
    results = ("metrics.ate_rmse_m", "summary.removed_beam_share", "metrics.time_to_m.median_delay",
               "summary.pose_confidence.lost_time_s", "summary.loop_closure.loops_accepted", "summary.scans")
    assert [c for c in timing if not is_timing_column(c)] == []
    assert [c for c in results if is_timing_column(c)] == []
