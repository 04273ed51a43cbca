"""Python on the engine: run(out=...) writes the command line's folder file for file, resumes a
killed run, runs shards the command line merges; arrays replay to the command line's bits."""
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

import hushfuse
from conftest import CENSORED_PF, EXAMPLE, cli, plain, read_json

FILES = ("summary.json", "per_step.csv", "scenario_as_run.toml")


def same_files(a, b, names=FILES):
    for name in names:
        assert (a / name).read_bytes() == (b / name).read_bytes(), name


def test_run_out_writes_the_command_lines_folder_with_the_paper_section(tmp_path):
    out = cli("reproduce", "dormann-fig1", "--trials", "6", "--out", "cli", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    got = hushfuse.run("dormann-fig1", trials=6, out=tmp_path / "py", reproduce=True)
    same_files(tmp_path / "cli", tmp_path / "py")
    # The in-memory result carries the same paper section as summary.json.
    expected = read_json(tmp_path / "cli" / "summary.json")
    assert "paper" in expected and got["paper"] == expected["paper"]
    assert "summary.json" in got["files"] and got["out"] == str(tmp_path / "py")
    # Without out=, the same summary (paper included), from memory.
    mem = hushfuse.run("dormann-fig1", trials=6)
    assert plain(mem["paper"]) == expected["paper"]


def test_shards_from_python_merge_to_the_unsharded_run(tmp_path, monkeypatch):
    (tmp_path / "pf.toml").write_text(CENSORED_PF.replace("trials = 6", "trials = 20"))
    monkeypatch.chdir(tmp_path)
    for i in (1, 2):
        r = hushfuse.run("pf.toml", out="shards", shard=(i, 2))
        assert r["shard"].endswith(f"shard-{i:04d}-of-0002.hfshard") and r["done"] is False
    again = hushfuse.run("pf.toml", out="shards", shard="2/2", resume=True)
    assert again["done"] is True
    merged = cli("merge", "shards", "--out", "merged", cwd=tmp_path)
    assert merged.returncode == 0, merged.stderr
    whole = cli("run", "pf.toml", "--out", "whole", cwd=tmp_path)
    assert whole.returncode == 0, whole.stderr
    same_files(tmp_path / "whole", tmp_path / "merged")


def test_a_killed_python_run_resumes_to_the_uninterrupted_result(tmp_path, monkeypatch):
    # Long enough to be killed mid-way (seconds), checkpointed after every window of blocks.
    scenario = CENSORED_PF.replace("trials = 6", "trials = 2000").replace("steps = 15", "steps = 200")
    (tmp_path / "pf.toml").write_text(scenario)
    code = (
        "import hushfuse; hushfuse.run('pf.toml', out='o', threads=1, checkpoint_every=0.0)"
    )
    child = subprocess.Popen([sys.executable, "-c", code], cwd=tmp_path)
    checkpoint = tmp_path / "o" / "hushfuse-checkpoint.bin"
    deadline = time.time() + 120
    while not checkpoint.exists() and child.poll() is None and time.time() < deadline:
        time.sleep(0.05)
    assert child.poll() is None, "the run ended before it could be killed: make it longer"
    assert checkpoint.exists(), "no checkpoint within two minutes"
    child.send_signal(signal.SIGKILL)
    child.wait()
    assert not (tmp_path / "o" / "summary.json").exists()
    monkeypatch.chdir(tmp_path)
    with pytest.raises(hushfuse.ScenarioError, match="resume"):
        hushfuse.run("pf.toml", out="o", threads=1)
    resumed = hushfuse.run("pf.toml", out="o", threads=2, resume=True)
    assert not checkpoint.exists()
    whole = cli("run", "pf.toml", "--out", "whole", cwd=tmp_path)
    assert whole.returncode == 0, whole.stderr
    same_files(tmp_path / "whole", tmp_path / "o")
    assert plain(resumed["schemes"]) == read_json(tmp_path / "whole" / "summary.json")["schemes"]


def test_arrays_replay_to_the_command_lines_bits(tmp_path):
    # Trial 2 of the example written by the command line, replayed from numpy arrays.
    scen = str(EXAMPLE / "scenario.toml")
    out = cli("run", scen, "--trials", "3", "--out", "o", "--write-trial", "2", "data", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    rep = cli(
        "replay", scen, "--measurements", "data/measurements.csv", "--truth", "data/truth.csv",
        "--trial", "2", "--out", "r", cwd=tmp_path,
    )
    assert rep.returncode == 0, rep.stderr
    d = hushfuse.simulate(scen, trial=2)
    r = hushfuse.replay(scen, d["measurements"], d["truth"], trial=2)
    assert plain(r["summary"]) == read_json(tmp_path / "r" / "summary.json")
    import csv

    with open(tmp_path / "r" / "estimates.csv") as f:
        rows = list(csv.DictReader(f))
    n = r["schemes"][0]["mean"].shape[1]
    for v, s in enumerate(r["schemes"]):
        mine = [row for row in rows if int(row["variant"]) == v]
        cli_mean = np.array([[float(row[f"mean_{j}"]) for j in range(n)] for row in mine])
        assert np.array_equal(cli_mean, s["mean"]), s["name"]


def test_run_options_that_need_a_folder_are_refused():
    with pytest.raises(ValueError, match="need out="):
        hushfuse.run("dormann-fig1", trials=2, resume=True)
    with pytest.raises(ValueError, match="shard"):
        hushfuse.run("dormann-fig1", trials=2, out="x", shard="3/2")


def test_loss_runs_as_the_command_lines_loss_with_loss_aware_copies(tmp_path):
    out = cli("run", "zheng-fig1", "--trials", "4", "--loss", "0.3", "--out", "cli", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    got = hushfuse.run("zheng-fig1", trials=4, loss=0.3, out=tmp_path / "py")
    same_files(tmp_path / "cli", tmp_path / "py")
    names = [s["name"] for s in got["schemes"]]
    assert "CFwMD (loss-aware)" in names and "CFwMD" in names
    aware = next(s for s in got["schemes"] if s["name"] == "CFwMD (loss-aware)")
    assert aware["params"]["link_loss"] == 0.3 and aware["link"]["lost"] > 0
    with pytest.raises(hushfuse.ScenarioError, match="--loss"):
        hushfuse.run("zheng-fig1", trials=4, loss=1.5)


def test_an_arena_out_writes_the_command_lines_folder(tmp_path):
    """budgets= with out= and report=True: the files of `hushfuse run --budgets --report
    --out`, byte for byte (the manifest and its hash included), but the seconds taken."""
    args = ("--budgets", "270,330", "--trials", "4", "--report")
    out = cli("run", "arena-1d", *args, "--out", "cli", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    got = hushfuse.run("arena-1d", trials=4, budgets=[270, 330], out=tmp_path / "py", report=True)
    manifest = read_json(tmp_path / "cli" / "hushfuse-manifest.json")
    assert manifest["kind"] == "arena" and got["files"] == manifest["files"]
    assert "report.html" in got["files"] and "budget-270/summary.json" in got["files"]
    same_files(tmp_path / "cli", tmp_path / "py",
               [n for n in got["files"] if n != "calibration.json"] + ["hushfuse-manifest.json"])
    a, b = (read_json(tmp_path / d / "calibration.json") for d in ("cli", "py"))
    del a["seconds"], b["seconds"]
    assert a == b
