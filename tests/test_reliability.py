"""Issue 14: never lose a user's data, fail before the work, bounded memory.

Every hostile input is generated here; each test reproduces one reported failure.
"""

from __future__ import annotations

import gzip
import hashlib
import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import run_cli

from dynslam2d.io.rosbag import write_scan_bag
from dynslam2d.sim import SimSource

SRC = str(Path(__file__).resolve().parents[1] / "src")


def cli(capsys, *args: str) -> tuple[int, str, str]:
    return run_cli(capsys, *args)


def tree_digest(path: Path) -> dict[str, str]:
    """Relative path -> sha1 of every file under ``path`` (or of ``path`` itself)."""
    if path.is_file():
        return {".": hashlib.sha1(path.read_bytes()).hexdigest()}
    return {str(p.relative_to(path)): hashlib.sha1(p.read_bytes()).hexdigest() if p.is_file() else "dir"
            for p in sorted(path.rglob("*"))}


def sim_bag(path: Path, duration: float = 1.5) -> Path:
    """A small LaserScan bag of the simulated paper scene."""
    return write_scan_bag(path, SimSource("paper", duration=duration))


def carmen_log(n: int = 40, beams: int = 90, t0: float = 1000.0) -> str:
    """FLASER lines of a robot standing in a 4 m × 6 m room (ranges to the walls)."""
    ang = -np.pi / 2 + np.pi * np.arange(beams) / (beams - 1)
    with np.errstate(divide="ignore"):
        rx = np.where(np.cos(ang) > 1e-9, 3.0 / np.cos(ang), np.inf)
        ry = np.where(np.abs(np.sin(ang)) > 1e-9, 2.0 / np.abs(np.sin(ang)), np.inf)
    r = np.minimum(rx, ry)
    lines = []
    for i in range(n):
        rr = " ".join(f"{v:.3f}" for v in r)
        t = t0 + 0.2 * i
        lines.append(f"FLASER {beams} {rr} 0 0 0 0 0 0 {t:.6f} host {t:.6f}")
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------- item 1, 2: --write-bag


def test_write_bag_never_deletes_an_existing_folder(tmp_path, capsys):
    keep = tmp_path / "keep"
    (keep / "sub").mkdir(parents=True)
    (keep / "notes.txt").write_text("x\n")
    before = tree_digest(keep)
    for extra in ((), ("--force",)):
        code, _, err = cli(capsys, "run", "sim:paper", "--duration", "1", "--out", str(tmp_path / "r"),
                           "--write-bag", str(keep), "-q", *extra)
        assert code == 2 and "--write-bag" in err and err.count("\n") == 1
        assert tree_digest(keep) == before
        assert not (tmp_path / "r").exists()  # refused before the work: no results folder either


def test_write_bag_never_overwrites_the_input(tmp_path, capsys):
    bag = sim_bag(tmp_path / "in.mcap")
    before = tree_digest(bag)
    for target in (bag, tmp_path / "." / "in.mcap"):
        for extra in ((), ("--force",)):
            code, _, err = cli(capsys, "run", str(bag), "--out", str(tmp_path / "r"), "--write-bag", str(target),
                               "-q", *extra)
            assert code == 2 and "input" in err, err
            assert tree_digest(bag) == before


def test_write_bag_force_replaces_only_its_own_bag_and_cleans_part_folders(tmp_path, capsys):
    out_bag = tmp_path / "out.mcap"
    code, _, err = cli(capsys, "run", "sim:paper", "--duration", "1", "--out", str(tmp_path / "r1"),
                       "--write-bag", str(out_bag), "-q")
    assert code == 0, err
    stale = tmp_path / ".out.mcap.x1y2.part"  # what a kill -9 during the bag write leaves
    stale.mkdir()
    (stale / "out.mcap").write_bytes(b"half")
    code, _, err = cli(capsys, "run", "sim:paper", "--duration", "1", "--out", str(tmp_path / "r2"),
                       "--write-bag", str(out_bag), "-q")
    assert code == 2 and "--force" in err  # exists: not replaced silently
    code, _, err = cli(capsys, "run", "sim:paper", "--duration", "1", "--out", str(tmp_path / "r3"),
                       "--write-bag", str(out_bag), "-q", "--force")
    assert code == 0, err
    assert not stale.exists()
    foreign = tmp_path / "foreign.mcap"
    sim_bag(foreign, 0.5)  # a bag, but not one dynslam2d wrote (no /slam_pose)
    before = tree_digest(foreign)
    code, _, err = cli(capsys, "run", "sim:paper", "--duration", "1", "--out", str(tmp_path / "r4"),
                       "--write-bag", str(foreign), "-q", "--force")
    assert code == 2 and "not a bag written by dynslam2d" in err
    assert tree_digest(foreign) == before


def test_write_bag_dot_is_one_clear_line(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, _, err = cli(capsys, "run", "sim:paper", "--duration", "1", "--out", "r", "--write-bag", ".", "-q")
    assert code == 2 and err.count("\n") == 1 and ".part" not in err and "--write-bag" in err


# ---------------------------------------------------------------- item 3, 9: pipes and FIFOs


def _run_module(args: list[str], **kw) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=SRC)
    return subprocess.run([sys.executable, "-m", "dynslam2d", *args], capture_output=True, env=env, timeout=300, **kw)


@pytest.mark.parametrize("gz", [False, True])
def test_carmen_log_through_a_pipe_loses_nothing(tmp_path, gz):
    text = carmen_log(n=80, beams=180).encode()
    assert len(text) > 4096 * 3  # the first 4 KB used to vanish while sniffing
    data = gzip.compress(text) if gz else text
    res = _run_module(["info", "/dev/stdin", "--json"], input=data)
    assert res.returncode == 0, res.stderr.decode(errors="replace")
    info = json.loads(res.stdout)
    assert info["scans"] == 80 and info["origin"] == "/dev/stdin"


def test_fifo_without_writer_fails_with_a_message(tmp_path, capsys, monkeypatch):
    import dynslam2d.io.sources as sources

    monkeypatch.setattr(sources, "STREAM_WAIT_S", 0.3)
    fifo = tmp_path / "scans.fifo"
    os.mkfifo(fifo)
    t = time.monotonic()
    code, _, err = cli(capsys, "info", str(fifo))
    assert code == 2 and "no data within" in err and err.count("\n") == 1
    assert time.monotonic() - t < 10


def test_fifo_with_a_writer_is_read_whole(tmp_path, capsys):
    fifo = tmp_path / "log.fifo"
    os.mkfifo(fifo)
    text = carmen_log(n=30).encode()

    def writer() -> None:
        with open(fifo, "wb") as fh:
            fh.write(text)

    th = threading.Thread(target=writer)
    th.start()
    code, out, err = cli(capsys, "info", str(fifo), "--json")
    th.join(5)
    assert code == 0, err
    assert json.loads(out)["scans"] == 30


# ---------------------------------------------------------------- item 5: the same --out twice


def test_second_run_into_the_same_out_leaves_no_stale_files(tmp_path, capsys):
    out = tmp_path / "r"
    code, _, err = cli(capsys, "run", "sim:paper", "--duration", "1.5", "--out", str(out), "--animate",
                       "--frame-step", "10", "-q")
    assert code == 0, err
    assert {"errors.png", "metrics.json", "run.gif"} <= {p.name for p in out.iterdir()}
    bag = sim_bag(tmp_path / "in.mcap")
    code, _, err = cli(capsys, "run", str(bag), "--out", str(out), "-q")
    assert code == 2 and "--force" in err  # an earlier results folder is not replaced silently
    code, _, err = cli(capsys, "run", str(bag), "--out", str(out), "-q", "--force")
    assert code == 0, err
    names = {p.name for p in out.iterdir()}
    assert not names & {"errors.png", "metrics.json", "run.gif"}  # no file of the first run survives
    assert json.loads((out / "run.json").read_text())["status"] == "complete"
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []  # no staging left


def test_foreign_non_empty_out_folder_is_refused_untouched(tmp_path, capsys):
    out = tmp_path / "thesis"
    out.mkdir()
    (out / "chapter1.tex").write_text("precious\n")
    before = tree_digest(out)
    code, _, err = cli(capsys, "run", "sim:paper", "--duration", "1", "--out", str(out), "-q", "--force")
    assert code == 2 and "not a dynslam2d results folder" in err
    assert tree_digest(out) == before


# ---------------------------------------------------------------- item 4: interrupts and checkpoints


def test_ctrl_c_leaves_a_checkpoint_and_says_where(tmp_path, capsys, monkeypatch):
    import dynslam2d.pipeline as pipeline

    real = pipeline.Pipeline.process
    calls = {"n": 0}

    def process(self, scan):
        calls["n"] += 1
        if calls["n"] == 31:
            raise KeyboardInterrupt
        return real(self, scan)

    monkeypatch.setattr(pipeline.Pipeline, "process", process)
    out = tmp_path / "r"
    code, _, err = cli(capsys, "run", "sim:paper", "--duration", "3", "--out", str(out), "-q",
                       "--write-bag", str(tmp_path / "b.mcap"))
    assert code == 130
    assert err.strip().splitlines()[-1] == f"interrupted after 30 scans, partial results in {out}"
    marker = json.loads((out / "run.json").read_text())
    assert marker["status"] == "incomplete" and marker["scans"] == 30
    assert json.loads((out / "summary.json").read_text())["status"] == "incomplete"
    traj = [ln for ln in (out / "trajectory.tum").read_text().splitlines() if not ln.startswith("#")]
    assert len(traj) == 30 and (out / "map.yaml").exists() and (out / "map.pgm").exists()
    assert not (tmp_path / "b.mcap").exists()
    assert [p.name for p in tmp_path.iterdir() if p.name.endswith(".part")] == []


def test_kill_9_leaves_the_last_checkpoint(tmp_path):
    out = tmp_path / "r"
    env = dict(os.environ, PYTHONPATH=SRC)
    proc = subprocess.Popen([sys.executable, "-m", "dynslam2d", "run", "sim:paper", "--duration", "60", "--out",
                             str(out),
                             "-q", "--checkpoint-scans", "20"], env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 240
        while time.monotonic() < deadline:
            m = out / "run.json"
            if m.exists() and json.loads(m.read_text()).get("scans", 0) >= 40:
                break
            time.sleep(0.2)
        else:
            pytest.fail("no checkpoint appeared")
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    marker = json.loads((out / "run.json").read_text())
    assert marker["status"] == "incomplete"
    traj = [ln for ln in (out / "trajectory.tum").read_text().splitlines() if not ln.startswith("#")]
    # run.json is written last in each checkpoint: a kill between two files of the next checkpoint
    # leaves a trajectory that is newer than the marker, never older
    assert len(traj) >= marker["scans"] >= 40
    assert (out / "map.yaml").exists()


# ---------------------------------------------------------------- item 10: every output checked first


@pytest.mark.parametrize("make_out", [
    lambda p: (p / "file.txt").write_text("x") and p / "file.txt",   # an existing file
    lambda p: (p / "file.txt").write_text("x") and p / "file.txt" / "sub",  # below a file
    lambda p: Path("/proc/dynslam2d-test"),
    lambda p: Path("/dev/null"),
])
def test_bad_out_fails_before_the_first_scan(tmp_path, capsys, monkeypatch, make_out):
    import dynslam2d.pipeline as pipeline

    out = make_out(tmp_path)
    monkeypatch.setattr(pipeline, "run", lambda *a, **k: pytest.fail("mapping started"))
    code, _, err = cli(capsys, "run", "sim:paper", "--duration", "1", "--out", str(out), "-q")
    assert code == 2 and "--out" in err and err.count("\n") == 1 and "Traceback" not in err
    code, _, err = cli(capsys, "simulate", "static", "--duration", "1", "--out", str(out))
    assert code == 2 and "--out" in err and err.count("\n") == 1


def test_bad_write_bag_and_gt_fail_before_the_first_scan(tmp_path, capsys, monkeypatch):
    import dynslam2d.pipeline as pipeline

    monkeypatch.setattr(pipeline, "run", lambda *a, **k: pytest.fail("mapping started"))
    (tmp_path / "f").write_text("x")
    for args, what in (
        (("--write-bag", str(tmp_path / "f" / "b.mcap")), "--write-bag"),
        (("--write-bag", "/proc/nope/b.mcap"), "--write-bag"),
        (("--gt", str(tmp_path / "nogt")), "nogt"),
    ):
        code, _, err = cli(capsys, "run", "sim:paper", "--duration", "1", "--out", str(tmp_path / "r"), "-q", *args)
        assert code == 2 and what in err and err.count("\n") == 1, err
        assert not (tmp_path / "r").exists()


# ---------------------------------------------------------------- item 11: user text is not markup


def test_paths_with_rich_markup_characters_print_plainly(tmp_path, capsys):
    d = tmp_path / "odd[" / "]name"
    d.mkdir(parents=True)
    log = d / "log[bold].clf"
    log.write_text(carmen_log(n=20))
    code, out, err = cli(capsys, "info", str(log))
    assert code == 0, err
    code, _, err = cli(capsys, "info", str(d / "missing[/].clf"))
    assert code == 2 and "missing[/].clf" in err
    out_dir = tmp_path / "r[/]x"
    code, out, err = cli(capsys, "run", str(log), "--out", str(out_dir), "--map-resolution", "0.1")
    assert code == 0, err
    assert str(out_dir) in out.replace("\n", "")


# ---------------------------------------------------------------- item 12, 19: one-line messages


def test_wrong_message_definition_on_a_laserscan_topic_is_one_line(tmp_path, capsys):
    import struct

    from rosbags.rosbag1 import Writer

    path = tmp_path / "wrong.bag"
    w = Writer(path)
    w.open()
    c = w.add_connection("/scan", "sensor_msgs/msg/LaserScan", msgdef="float64 data\n",
                         md5sum="fdb28210bfa9d7c91146260178d9a584")
    for i in range(3):
        w.write(c, 10**9 * (i + 1), struct.pack("<d", 1.0 + i))
    w.close()
    code, _, err = cli(capsys, "info", str(path))
    assert code == 2 and err.count("\n") == 1 and "not a valid sensor_msgs/LaserScan" in err


@pytest.mark.parametrize("content, expect", [
    (b"slam:\n  map_resolution: 0.1 # \xe9t\xe9\n", "not UTF-8"),
    (b"slam:\n  map_resolution: [0.1\n", "not valid YAML"),
    (b"slam:\n  map_resolution: .nan\n", "finite number"),
])
def test_config_file_errors_are_one_line(tmp_path, capsys, content, expect):
    cfg = tmp_path / "c.yaml"
    cfg.write_bytes(content)
    code, _, err = cli(capsys, "run", "sim:paper", "--duration", "1", "--config", str(cfg), "--out",
                       str(tmp_path / "r"))
    assert code == 2 and expect in err and err.count("\n") == 1 and "c.yaml" in err
    assert not (tmp_path / "r").exists()


def test_option_errors_are_one_line(tmp_path, capsys):
    bag = sim_bag(tmp_path / "in.mcap", 0.5)
    for args, expect in (
        (("sim:paper", "--duration", "1", "--map-resolution", "nan"), "--map-resolution must be a finite number"),
        ((str(bag), "--topic", ""), "--topic is empty"),
        ((str(bag), "--duration", "3"), "sim:<scenario> inputs only"),
        ((str(bag), "--seed", "3"), "sim:<scenario> inputs only"),
    ):
        code, _, err = cli(capsys, "run", *args, "--out", str(tmp_path / "r"))
        assert code == 2 and expect in err and err.count("\n") == 1, err
    code, _, err = cli(capsys, "info", str(bag), "--seed", "1")
    assert code == 2 and "sim:<scenario> inputs only" in err


def test_truncated_ros1_bag_suggests_reindex(tmp_path, capsys):
    bag = write_scan_bag(tmp_path / "t.bag", SimSource("paper", duration=1.0))
    data = bag.read_bytes()
    cut = tmp_path / "cut.bag"
    cut.write_bytes(data[: len(data) * 2 // 3])
    code, _, err = cli(capsys, "run", str(cut), "--out", str(tmp_path / "r"), "-q")
    assert code == 2 and "rosbag reindex" in err and err.count("\n") == 1


# ---------------------------------------------------------------- item 13, 14: maps that cannot be built


def test_absurd_map_resolution_is_an_error_not_a_1x1_map(tmp_path, capsys):
    for res in ("1e-3", "1e-4"):
        code, _, err = cli(capsys, "run", "sim:paper", "--duration", "1", "--map-resolution", res,
                           "--out", str(tmp_path / "r"), "-q")
        assert code == 2 and "--map-resolution" in err and err.count("\n") == 1, err
        assert not (tmp_path / "r").exists()


@pytest.mark.parametrize("ranges", ["0.000", "nan", "inf"])
def test_recording_without_usable_returns_exits_non_zero(tmp_path, capsys, ranges):
    lines = [f"FLASER 90 {' '.join([ranges] * 90)} 0 0 0 0 0 0 {100 + 0.2 * i:.3f} h {100 + 0.2 * i:.3f}"
             for i in range(15)]
    log = tmp_path / "empty.clf"
    log.write_text("\n".join(lines) + "\n")
    code, _, err = cli(capsys, "run", str(log), "--out", str(tmp_path / "r"), "-q")
    assert code == 2 and "usable returns" in err and err.count("\n") == 1
    assert not (tmp_path / "r").exists()


# ---------------------------------------------------------------- item 17: eval refuses what it cannot score


def test_eval_ate_refuses_fewer_than_three_poses(tmp_path, capsys):
    ref = tmp_path / "ref.tum"
    est = tmp_path / "est.tum"
    ref.write_text("1.0 0 0 0 0 0 0 1\n2.0 1 0 0 0 0 0 1\n")
    est.write_text("1.0 0 0 0 0 0 0 1\n2.0 1.5 0 0 0 0 0 1\n")
    code, _, err = cli(capsys, "eval", "ate", str(ref), str(est))
    assert code == 2 and "at least 3" in err and err.count("\n") == 1


def test_eval_relations_refuses_a_tum_file(tmp_path, capsys):
    est = tmp_path / "est.tum"
    yaw = np.linspace(0, 2, 10)
    est.write_text("".join(f"{100 + i:.1f} {i * 0.5:.2f} 0 0 0 0 {np.sin(y / 2):.6f} {np.cos(y / 2):.6f}\n"
                           for i, y in enumerate(yaw)))
    code, _, err = cli(capsys, "eval", "relations", str(est), str(est))
    assert code == 2 and "TUM trajectory" in err and err.count("\n") == 1


# ---------------------------------------------------------------- item 6: simulator duration


def test_huge_simulated_duration_is_refused_at_once(capsys):
    t = time.monotonic()
    code, _, err = cli(capsys, "info", "sim:paper", "--duration", "1e7")
    assert code == 2 and "limit" in err and err.count("\n") == 1
    assert time.monotonic() - t < 20


# ---------------------------------------------------------------- item 15, 16: --skip-bad and stamp repairs


def test_skip_bad_counts_every_kind_of_skip_in_run(tmp_path, capsys):
    good = carmen_log(n=40).splitlines()
    lines = list(good)
    lines[5] = "FLASER 90 1 2 3"  # malformed
    lines[9] = "FLASER 90 junk"  # malformed
    lines[20] = good[19]  # same stamp as the previous scan: nudged (repaired), not dropped
    log = tmp_path / "bad.clf"
    log.write_text("\n".join(lines) + "\n")
    code, _, err = cli(capsys, "run", str(log), "--out", str(tmp_path / "r"), "-q")
    assert code == 2 and ":6:" in err  # without --skip-bad the first bad line stops the run
    code, out, err = cli(capsys, "run", str(log), "--out", str(tmp_path / "r"), "--skip-bad", "--map-resolution", "0.1")
    assert code == 0, err
    flat = " ".join(out.split())
    assert "2 malformed lines" in flat and "nudged" in flat.replace("stamps did not increase", "nudged")
    summary = json.loads((tmp_path / "r" / "summary.json").read_text())
    assert summary["input_skipped"]["malformed_lines"] == 2 and summary["input_skipped_total"] == 2
    assert summary["stamp_repairs"]["nudged_stamps"] == 1
    assert 0 < summary["stamp_repairs"]["largest_nudge_s"] <= 2e-6
    assert summary["scans"] == 38


def test_skip_bad_skips_malformed_ros_messages_and_counts_them(tmp_path, capsys):
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC)
    LaserScan = ts.types["sensor_msgs/msg/LaserScan"]
    Header = ts.types["std_msgs/msg/Header"]
    Time = ts.types["builtin_interfaces/msg/Time"]
    path = tmp_path / "mixed.bag"
    w = Writer(path)
    w.open()
    c = w.add_connection("/scan", LaserScan.__msgtype__, typestore=ts)
    src = list(SimSource("static", duration=1.0))
    bad = {3, 7}
    for i, scan in enumerate(src):
        t_ns = int(round(scan.stamp * 1e9)) + 10**9
        if i in bad:
            w.write(c, t_ns, b"\x01\x02\x03")  # cut-off message
            continue
        msg = LaserScan(Header(seq=i, stamp=Time(sec=t_ns // 10**9, nanosec=t_ns % 10**9), frame_id="laser"),
                        np.float32(scan.angle_min), np.float32(scan.angle_max), np.float32(scan.angle_increment),
                        np.float32(0), np.float32(0), np.float32(scan.range_min), np.float32(scan.range_max),
                        scan.ranges.astype(np.float32), np.zeros(0, dtype=np.float32))
        w.write(c, t_ns, ts.serialize_ros1(msg, LaserScan.__msgtype__))
    w.close()
    code, _, err = cli(capsys, "run", str(path), "--out", str(tmp_path / "r"), "-q")
    assert code == 2 and "message index 3" in err and "--skip-bad" in err
    code, out, err = cli(capsys, "run", str(path), "--out", str(tmp_path / "r"), "--skip-bad", "--json")
    assert code == 0, err
    summary = json.loads(out)
    assert summary["input_skipped"]["malformed_messages"] == 2
    assert summary["scans"] == len(src) - 2


def test_repeated_large_stamps_move_by_the_smallest_step(tmp_path):
    from dynslam2d.io.carmen import CarmenSource

    t = 1.0e12  # float64 spacing here is 1.2e-4 s: 1 µs cannot be represented
    lines = carmen_log(n=4, t0=t).splitlines()
    lines[2] = lines[1]
    log = tmp_path / "big.clf"
    log.write_text("\n".join(lines) + "\n")
    src = CarmenSource(log)
    stamps = np.array([s.stamp for s in src])
    assert np.all(np.diff(stamps) > 0)
    assert stamps[2] == np.nextafter(stamps[1], np.inf)
    assert src.meta.extra["largest_nudge_s"] == stamps[2] - stamps[1] < 1e-3


# ---------------------------------------------------------------- item 7, 8: memory and figure cost


def _room_log(path: Path, n: int) -> Path:
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    try:
        from bench_memory import write_log
    finally:
        sys.path.pop(0)
    write_log(path, n)
    return path


def test_carmen_source_streams_instead_of_holding_the_log(tmp_path):
    import tracemalloc

    from dynslam2d.io.carmen import CarmenSource

    peaks = {}
    for n in (300, 3000):
        log = _room_log(tmp_path / f"l{n}.clf", n)
        tracemalloc.start()
        src = CarmenSource(log)
        count = sum(1 for _ in src)
        peaks[n] = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        assert count == n == len(src)
    # 10× the scans: the index grows by ~40 bytes per scan, the scans themselves are not kept
    # (holding them would cost > 1.5 KB per scan, > 4 MB more for 3000 scans).
    assert peaks[3000] - peaks[300] < 1_000_000, peaks


def test_per_scan_records_are_compact_and_read_back_exactly():
    from dynslam2d.records import BitRows, GrowArray, TrackRows

    rng = np.random.default_rng(1)
    rows = [rng.random(n) < 0.3 for n in [360] * 50 + [361, 5, 0]]
    bits = BitRows()
    for r in rows:
        bits.append(r)
    assert len(bits) == len(rows) and all(np.array_equal(a, b) for a, b in zip(bits, rows))
    assert bits.total_set == sum(int(r.sum()) for r in rows) and not bits.uniform
    assert bits.nbytes < 64 * 1024  # 53 rows: packed bits + indexes, not 53 numpy objects of 360 bytes
    tracks = TrackRows()
    want = [(100.0 + i, i % 7, ("tentative", "confirmed", "coasting")[i % 3], 1.25 * i, -0.5 * i, 0.125, 0.5, 0.25,
             0.5, -0.25, bool(i % 2)) for i in range(20)]
    for row in want:
        tracks.append(row)
    assert list(tracks) == want and tracks[3] == want[3]
    grow = GrowArray(np.float64, (3,))
    for i in range(1000):
        grow.append((i, -i, 0.5 * i))
    assert np.array(grow).shape == (1000, 3) and grow[-1].tolist() == [999.0, -999.0, 499.5] and len(grow) == 1000


def test_run_memory_per_scan_is_small(tmp_path):
    from dynslam2d.config import Config
    from dynslam2d.pipeline import run

    res = run(SimSource("paper", duration=2.0), Config())
    compact = res.removed_rows.nbytes + res.track_rows.nbytes  # allocated capacity, slack included
    # What the same records cost as a list of bool arrays and a list of tuples of Python numbers.
    as_lists = sum(sys.getsizeof(r) for r in res.removed_rows) + sum(
        sys.getsizeof(row) + sum(sys.getsizeof(v) for v in row) for row in res.track_rows)
    assert compact < 0.5 * as_lists, (compact, as_lists)  # even with up to 2x growth slack
    assert res.removed.shape == (res.n_scans, 720) and res.summary()["scans"] == res.n_scans


def test_tracks_figure_draws_one_collection_per_kind_and_caps_labels(tmp_path, monkeypatch):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from dynslam2d.types import Box
    from dynslam2d.viz import tracksplot
    from dynslam2d.viz.trackpaths import TrackPath

    rng = np.random.default_rng(0)
    tracks = []
    for i in range(2000):
        n = int(rng.integers(2, 30))
        xy = np.cumsum(rng.normal(0, 0.1, (n, 2)), axis=0) + rng.uniform(-20, 20, 2)
        tracks.append(TrackPath(i, np.arange(n, dtype=float), xy, rng.normal(0, 1, (n, 2)), rng.random(n) < 0.5,
                                np.array(["confirmed"] * n), Box(*xy[-1], 0.0, 0.5, 0.5)))
    seen = {}
    real_save = tracksplot.save_png
    from matplotlib.collections import LineCollection  # (tracks.png's are a subclass: pass mem46)

    def spy(fig, path, dpi):
        ax = fig.axes[0]
        seen["collections"] = len([c for c in ax.collections if isinstance(c, LineCollection)])
        seen["labels"] = len([t for t in ax.texts if type(t).__name__ == "Annotation" and t.get_text().isdigit()])
        return real_save(fig, path, dpi)

    monkeypatch.setattr(tracksplot, "save_png", spy)
    tracksplot.plot_tracks(tmp_path / "t.png", tracks, None, dpi=40)
    plt.close("all")
    assert seen["collections"] <= 2 and seen["labels"] <= tracksplot.MAX_LABELS
    assert (tmp_path / "t.png").stat().st_size > 0


# ---------------------------------------------------------------- property: hostile inputs never hurt

from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

_RESULT_FILES = ("map.yaml", "map.pgm", "map_logodds.npy", "trajectory.tum", "tracks.csv", "kept_mask.npz",
                 "config.yaml", "summary.json", "map.png", "tracks.png", "run.json")


def _corrupt(data: bytes, draw) -> bytes:
    """Apply 1-3 random corruptions: cut, flip bytes, duplicate or drop a chunk, insert junk."""
    for _ in range(draw(st.integers(1, 3))):
        if not data:
            break
        op = draw(st.sampled_from(["cut", "flip", "dup", "drop", "junk"]))
        i = draw(st.integers(0, len(data) - 1))
        if op == "cut":
            data = data[:i]
        elif op == "flip":
            data = data[:i] + bytes([data[i] ^ draw(st.integers(1, 255))]) + data[i + 1:]
        elif op == "dup":
            j = min(len(data), i + draw(st.integers(1, 400)))
            data = data[:j] + data[i:j] + data[j:]
        elif op == "drop":
            data = data[:i] + data[min(len(data), i + draw(st.integers(1, 400))):]
        else:
            data = data[:i] + draw(st.binary(min_size=1, max_size=40)) + data[i:]
    return data


def _check_run_on(path: Path, skip_bad: bool, capsys) -> None:
    base = path.parent
    foreign = base / "notes.txt"
    foreign.write_text("the user's own file\n")
    before = {p.name: tree_digest(p) for p in base.iterdir()}
    out = base / "out"
    args = ["run", str(path), "--out", str(out), "-q", "--map-resolution", "0.1"] + (["--skip-bad"] if skip_bad else [])
    code, _, err = cli(capsys, *args)
    assert "Traceback" not in err
    assert {p.name: tree_digest(p) for p in base.iterdir() if p.name != "out"} == before  # inputs untouched
    if code == 0:
        assert all((out / name).is_file() for name in _RESULT_FILES), sorted(p.name for p in out.iterdir())
        assert json.loads((out / "run.json").read_text())["status"] == "complete"
    else:
        assert code == 2, (code, err)
        lines = err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("error:"), err
        assert not out.exists()


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data(), gz=st.booleans(), skip_bad=st.booleans())
def test_run_on_corrupted_carmen_logs_is_clean(capsys, data, gz, skip_bad):
    import tempfile

    base = Path(tempfile.mkdtemp(prefix="dynslam2d-prop-"))
    try:
        raw = carmen_log(n=data.draw(st.integers(3, 12)), beams=60).encode()
        raw = gzip.compress(raw) if gz else raw
        path = base / ("log.clf.gz" if gz else "log.clf")
        path.write_bytes(_corrupt(raw, data.draw))
        _check_run_on(path, skip_bad, capsys)
    finally:
        import shutil

        shutil.rmtree(base, ignore_errors=True)


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data(), suffix=st.sampled_from([".mcap", ".bag"]), skip_bad=st.booleans())
def test_run_on_corrupted_bags_is_clean(capsys, data, suffix, skip_bad):
    import shutil
    import tempfile

    base = Path(tempfile.mkdtemp(prefix="dynslam2d-prop-"))
    try:
        clean = write_scan_bag(base / f"clean{suffix}", SimSource("static", duration=0.5, beams=60))
        raw = clean.read_bytes()
        clean.unlink()
        path = base / f"scans{suffix}"
        path.write_bytes(_corrupt(raw, data.draw))
        _check_run_on(path, skip_bad, capsys)
    finally:
        shutil.rmtree(base, ignore_errors=True)


@pytest.mark.parametrize("kind", ["truncated-gzip", "binary"])
def test_garbage_through_a_pipe_is_one_printable_line(kind):
    rng = np.random.default_rng(3)
    if kind == "truncated-gzip":
        whole = gzip.compress(carmen_log(n=60).encode())
        data = whole[: len(whole) // 2]
    else:
        data = b"FLASER 3 1 2 " + rng.integers(0, 256, 3000, dtype=np.uint8).tobytes()
    res = _run_module(["info", "/dev/stdin"], input=data)
    err = res.stderr.decode("utf-8")
    assert res.returncode == 2 and err.count("\n") == 1 and err.startswith("error: /dev/stdin")
    assert err.isascii() or all(ch.isprintable() or ch == "\n" for ch in err)
    assert len(err) < 400


def test_interrupt_while_writing_results_leaves_an_incomplete_marker(tmp_path, capsys, monkeypatch):
    import dynslam2d.results as results

    def boom(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(results, "write_figures", boom)
    out = tmp_path / "r"
    code, _, err = cli(capsys, "run", "sim:paper", "--duration", "1", "--out", str(out), "-q")
    assert code == 130 and "partial results in" in err
    assert json.loads((out / "run.json").read_text())["status"] == "incomplete"
    assert not (out / "map.png").exists()


def test_interrupted_replacement_keeps_the_earlier_complete_results(tmp_path, capsys, monkeypatch):
    import dynslam2d.pipeline as pipeline

    out = tmp_path / "r"
    code, _, err = cli(capsys, "run", "sim:paper", "--duration", "1", "--out", str(out), "-q")
    assert code == 0, err
    before = tree_digest(out)
    real = pipeline.Pipeline.process
    calls = {"n": 0}

    def process(self, scan):
        calls["n"] += 1
        if calls["n"] == 11:
            raise KeyboardInterrupt
        return real(self, scan)

    monkeypatch.setattr(pipeline.Pipeline, "process", process)
    code, _, err = cli(capsys, "run", "sim:paper", "--duration", "2", "--out", str(out), "-q", "--force")
    assert code == 130
    assert tree_digest(out) == before  # the complete earlier run is still there
    partial = [p for p in tmp_path.iterdir() if p.name.startswith("r.incomplete-")]
    assert len(partial) == 1 and f"partial results in {partial[0]}" in " ".join(err.split())
    assert json.loads((partial[0] / "run.json").read_text())["scans"] == 10


def test_eval_refuses_an_interrupted_results_folder(tmp_path, capsys):
    gt = tmp_path / "gt"
    code, _, err = cli(capsys, "simulate", "static", "--duration", "1", "--out", str(gt))
    assert code == 0, err
    out = tmp_path / "r"
    code, _, err = cli(capsys, "run", str(gt / "scans.mcap"), "--out", str(out), "-q")
    assert code == 0, err
    marker = json.loads((out / "run.json").read_text())
    marker["status"] = "incomplete"
    (out / "run.json").write_text(json.dumps(marker))
    code, _, err = cli(capsys, "eval", str(out), "--gt", str(gt))
    assert code == 2 and "interrupted run" in err


def test_refused_force_replacement_leaves_no_staging_folder(tmp_path, capsys):
    out = tmp_path / "r"
    code, _, err = cli(capsys, "run", "sim:paper", "--duration", "1", "--out", str(out), "-q")
    assert code == 0, err
    before = tree_digest(out)
    keep = tmp_path / "keep"
    keep.mkdir()
    code, _, err = cli(capsys, "run", "sim:paper", "--duration", "1", "--out", str(out), "-q", "--force",
                       "--write-bag", str(keep))
    assert code == 2
    code, _, err = cli(capsys, "simulate", "nope", "--out", str(out), "--force")
    assert code == 2
    assert tree_digest(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep", "r"]
