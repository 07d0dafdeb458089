"""Data-parallel fitting on torch.distributed (issue 33), on gloo ranks of this machine, one
Warp thread each (``WARPTEX_NUM_THREADS=1``):

- two ranks fit the default problem as one process does, to float rounding: ``warptex fit`` under
  ``torchrun --nproc-per-node 2`` and across two torchrun "nodes" (c10d rendezvous), and
  ``examples/torch_fit.py`` under torchrun;
- what the number of ranks does to the bits (``tests/dist_worker.py``): every rank holds the same
  parameters, a run is reproducible bit for bit at a given rank count, a one-rank group is the
  plain fit bit for bit, and 2 or 3 ranks agree with one process to float rounding only;
- one rank's bad input, settings that differ and diverged parameters raise on every rank;
- a rank killed, or stopped, mid-fit ends the run with an error within 60 s and leaves the
  previous output set as it was;
- ranks that check one new output folder at once all pass.

The tests that run ranks skip without PyTorch (the distributed fit needs torch.distributed).
"""

from __future__ import annotations

import importlib.util
import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from warptex import io
from warptex.apps.cli import main as cli_main

from warptex.apps.distributed import from_environment
from warptex.fit import shard

try:
    import torch.distributed as dist

    GLOO = dist.is_available() and dist.is_gloo_available()
except ImportError:
    dist, GLOO = None, False
linux = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="finds torchrun's processes in /proc")
needs_gloo = pytest.mark.skipif(not GLOO, reason="needs PyTorch with torch.distributed's gloo backend (pip install torch)")

ROOT = Path(__file__).resolve().parents[1]
FIT = ["fit", "--iters", "6", "--resolution", "32x40", "--report-every", "0"]
# |weight difference| allowed between 1 and 2 ranks after 6 iterations. Measured: 6e-7 for the native
# fit, 3e-5 for examples/torch_fit.py (the tiling scan's summed losses move its parabola's vertex in
# the last bits, and Adam's first steps, which normalise each gradient, carry that on).
WEIGHT_ROUNDING = 1e-4


# -- the split and the environment (no PyTorch needed) ----------------------------------------------------


def test_shard_deals_views_out_as_distributed_sampler_does():
    views = [f"view {k}" for k in range(7)]
    assert [shard(views, rank=r, world_size=3) for r in range(3)] == [["view 0", "view 3", "view 6"], ["view 1", "view 4"], ["view 2", "view 5"]]
    assert shard(views, rank=0, world_size=1) == views
    assert sorted(v for r in range(7) for v in shard(views, rank=r, world_size=7)) == sorted(views)
    with pytest.raises(ValueError, match=r"shard\(\): 3 ranks need at least 3 views \(one each\), got 2"):
        shard(views[:2], rank=0, world_size=3)
    with pytest.raises(ValueError, match=r"shard\(\): rank must be < world_size = 2, got 2"):
        shard(views, rank=2, world_size=2)
    with pytest.raises(ValueError, match=r"shard\(\): world_size must be an int >= 1, got 0"):
        shard(views, rank=0, world_size=0)


def test_torchrun_environment(monkeypatch):
    for name in ("WORLD_SIZE", "RANK", "LOCAL_RANK", "LOCAL_WORLD_SIZE"):
        monkeypatch.delenv(name, raising=False)
    assert from_environment() is None  # not started by torchrun
    monkeypatch.setenv("WORLD_SIZE", "1")
    monkeypatch.setenv("RANK", "0")
    assert from_environment() is None  # one process: the plain fit
    monkeypatch.setenv("WORLD_SIZE", "4")
    monkeypatch.setenv("RANK", "3")
    monkeypatch.setenv("LOCAL_RANK", "1")
    monkeypatch.setenv("LOCAL_WORLD_SIZE", "2")
    job = from_environment()
    assert (job.rank, job.world_size, job.local_rank, job.local_world_size) == (3, 4, 1, 2)
    assert str(job.device("cpu")) == "cpu"
    monkeypatch.setenv("RANK", "4")
    with pytest.raises(ValueError, match=r"fit: torchrun gave RANK=4 and WORLD_SIZE=4; expected 0 <= RANK < WORLD_SIZE"):
        from_environment()
    monkeypatch.setenv("RANK", "x")
    with pytest.raises(ValueError, match=r"fit: WORLD_SIZE is set, so this is a torchrun job, but RANK='x' is not a whole number"):
        from_environment()


def _env() -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("RANK", "WORLD_SIZE", "LOCAL_RANK", "LOCAL_WORLD_SIZE", "MASTER_ADDR", "MASTER_PORT")}
    env.update(WARPTEX_NUM_THREADS="1", OMP_NUM_THREADS="1", PYTHONUNBUFFERED="1", PYTHONPATH=str(ROOT))
    return env


def _torchrun(*args: str, nproc: int = 2) -> list[str]:
    return [sys.executable, "-m", "torch.distributed.run", "--standalone", f"--nproc-per-node={nproc}", *args]


def _run(command: list[str], cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run(command, cwd=cwd, env=_env(), capture_output=True, text=True, timeout=300)


def _fitted(folder: Path) -> tuple[np.ndarray, dict]:
    return io.read_image(folder / "splat_fitted.exr"), json.loads((folder / "summary.json").read_text())


def _one_process_fit(out: Path, monkeypatch) -> tuple[np.ndarray, dict]:
    monkeypatch.setenv("WARPTEX_NUM_THREADS", "1")
    assert cli_main([*FIT, "--out", str(out)]) == 0
    return _fitted(out)


def _same_fit(one, two) -> None:
    (w1, s1), (w2, s2) = one, two
    assert s1["world_size"] == 1 and s2["world_size"] == 2
    assert np.abs(w2 - w1).max() <= WEIGHT_ROUNDING, np.abs(w2 - w1).max()
    np.testing.assert_allclose(s2["fitted_tiling"], s1["fitted_tiling"], rtol=1e-5)
    assert s2["final_psnr_db"] == pytest.approx(s1["final_psnr_db"], abs=1e-3)
    assert s2["final_psnr_db"] > s2["initial_psnr_db"] + 3  # a fit, not a copy of the start
    assert s2["iterations"] == 6 and s2["views"] == 2


@needs_gloo
def test_torchrun_two_ranks_fit_the_default_problem_as_one_process_does(tmp_path, monkeypatch):
    two = _run(_torchrun("-m", "warptex", *FIT, "--out", str(tmp_path / "two")), tmp_path)
    assert two.returncode == 0, two.stderr[-3000:]
    fitted = _fitted(tmp_path / "two")
    _same_fit(_one_process_fit(tmp_path / "one", monkeypatch), fitted)
    assert two.stdout.count("wrote ") == len(fitted[1]["files"]) == 10  # rank 0 alone writes (and prints)
    assert "fit: 6 iterations on 2 processes" in two.stdout
    assert [p.name for p in (tmp_path / "two").iterdir() if p.name.startswith(".")] == []


@needs_gloo
def test_two_torchrun_nodes_meet_at_a_rendezvous_endpoint(tmp_path, monkeypatch):
    # What the docs say for several machines (docs/processes.md), with both "machines" here: one torchrun per node,
    # the same c10d rendezvous endpoint and id.
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    rdzv = ["--nnodes=2", "--nproc-per-node=1", "--rdzv-backend=c10d", f"--rdzv-endpoint=127.0.0.1:{port}", "--rdzv-id=warptex-test"]
    command = [sys.executable, "-m", "torch.distributed.run", *rdzv, "-m", "warptex", *FIT, "--out", str(tmp_path / "two")]
    nodes = [subprocess.Popen(command, cwd=tmp_path, env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for _ in range(2)]
    outputs = [node.communicate(timeout=300) for node in nodes]
    assert [node.returncode for node in nodes] == [0, 0], outputs[0][1][-2000:] + outputs[1][1][-2000:]
    assert sum(out.count("wrote ") for out, _ in outputs) == 10  # one rank, on one node, wrote
    _same_fit(_one_process_fit(tmp_path / "one", monkeypatch), _fitted(tmp_path / "two"))


@needs_gloo
def test_torch_fit_example_on_two_ranks_matches_one_process(tmp_path):
    example = str(ROOT / "examples" / "torch_fit.py")
    args = ["--iters", "6", "--resolution", "32x40"]
    two = _run(_torchrun(example, *args, "--out", str(tmp_path / "two")), tmp_path)
    assert two.returncode == 0, two.stderr[-3000:]
    one = _run([sys.executable, example, *args, "--out", str(tmp_path / "one")], tmp_path)
    assert one.returncode == 0, one.stderr[-3000:]
    (w1, s1), (w2, s2) = _fitted(tmp_path / "one"), _fitted(tmp_path / "two")
    assert (s1["world_size"], s2["world_size"]) == (1, 2) and two.stdout.count("PSNR") == 1
    assert np.abs(w2 - w1).max() <= WEIGHT_ROUNDING, np.abs(w2 - w1).max()
    assert s2["tiling"] == pytest.approx(s1["tiling"], rel=1e-5) and s2["psnr"] == pytest.approx(s1["psnr"], abs=1e-3)
    assert np.abs(w1 - 0.25).max() > 1e-3  # the weights moved from the uniform start


# -- the bits, and errors every rank reports ------------------------------------------------------------


def _worker():
    spec = importlib.util.spec_from_file_location("dist_worker", ROOT / "tests" / "dist_worker.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@needs_gloo
def test_what_the_number_of_ranks_does_to_the_bits(tmp_path, monkeypatch):
    monkeypatch.setenv("WARPTEX_NUM_THREADS", "1")
    (tmp_path / "1").mkdir()
    _worker().main(tmp_path / "1")
    one = np.load(tmp_path / "1" / "rank0.npz")
    params = ("logits", "log_tiling")
    for ranks in (2, 3):
        folder = tmp_path / str(ranks)
        folder.mkdir()
        done = _run(_torchrun(str(ROOT / "tests" / "dist_worker.py"), str(folder), nproc=ranks), tmp_path)
        assert done.returncode == 0, done.stderr[-3000:]
        runs = [np.load(folder / f"rank{r}.npz") for r in range(ranks)]
        for r, run in enumerate(runs):
            assert int(run["world_size"]) == ranks
            for k in params:  # every rank holds rank 0's bits, and a second fit gives them again
                np.testing.assert_array_equal(run[k], runs[0][k], err_msg=f"{ranks} ranks: rank {r}'s {k}")
                np.testing.assert_array_equal(run[f"{k}_again"], run[k], err_msg=f"{ranks} ranks: rank {r}'s second fit")
                np.testing.assert_array_equal(run[f"{k}_moved"], run[k], err_msg=f"{ranks} ranks: rank {r} started elsewhere")
        first = runs[0]
        # Against one process: float rounding (each rank backpropagates its views' texel gradients
        # through the softmax before they are summed), not the same bits.
        np.testing.assert_allclose(first["logits"], one["logits"], atol=1e-5)
        np.testing.assert_allclose(first["log_tiling"], one["log_tiling"], atol=1e-6)
        np.testing.assert_allclose(first["loss"], one["loss"], rtol=1e-6)
        assert float(first["final_mse"]) == pytest.approx(float(one["final_mse"]), rel=1e-6)
        assert not np.array_equal(first["logits"], one["logits"]), "bit-identical across rank counts: update the docs"
        for r in range(ranks):
            messages = json.loads((folder / f"rank{r}.json").read_text())
            bad = messages["bad view on rank 1"]
            assert "the target is (20, 23) (H, W) but its G-buffer is (20, 24)" in bad
            assert bad.startswith("ValueError: fit_splat(): view 0:" if r == 1 else f"ValueError: fit_splat(): rank 1 of {ranks} failed its input checks")
            assert "they differ in entropy: rank 0 0.001, rank 1 0.002" in messages["entropy differs"]
            assert messages["parameters differ"].startswith("DistributedError: check(): the ranks' parameters differ after the fit")
            assert messages["works after the errors"] == "no error"


@needs_gloo
def test_a_one_rank_group_fits_the_same_bits_as_no_group(tmp_path, monkeypatch):
    monkeypatch.setenv("WARPTEX_NUM_THREADS", "1")
    worker = _worker()
    views, layers = worker.scene()
    plain, result = worker.fit(views, layers, None)
    assert result.world_size == 1
    dist.init_process_group("gloo", init_method=f"file://{tmp_path / 'store'}", rank=0, world_size=1)
    group = dist.group.WORLD
    try:
        grouped, result = worker.fit(views, layers, group)
    finally:
        dist.destroy_process_group()
    assert result.world_size == 1
    for k in ("logits", "log_tiling"):
        np.testing.assert_array_equal(getattr(grouped, k).numpy(), getattr(plain, k).numpy())
    with pytest.raises(ValueError, match=r"fit_splat\(\): torch.distributed is not initialised; call torch.distributed.init_process_group\(\) first"):
        worker.fit(views, layers, group)  # a group of a job that was left
    with pytest.raises(TypeError, match=r"fit_splat\(\): process_group must be a torch.distributed ProcessGroup \(e.g. torch.distributed.group.WORLD\), got str"):
        worker.fit(views, layers, "gloo")


# -- failures --------------------------------------------------------------------------------------------


def _children(pid: int) -> list[int]:
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                if int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1]) == pid:
                    found.append(int(entry.name))
            except (OSError, IndexError, ValueError):
                pass
    return found


def _rank_pid(agent: int, rank: int) -> int:
    for pid in _children(agent):
        try:
            if f"RANK={rank}".encode() in (Path("/proc") / str(pid) / "environ").read_bytes().split(b"\0"):
                return pid
        except OSError:
            pass
    raise AssertionError(f"no rank {rank} among torchrun's processes")


def _previous_set(out: Path) -> dict:
    out.mkdir()
    (out / "summary.json").write_text('{"previous": true}\n')
    (out / "fitted.png").write_bytes(b"a previous run's picture")
    return {p.name: (p.read_bytes(), p.stat().st_mtime_ns) for p in out.iterdir()}


def _fit_and_stop_rank_1(tmp_path: Path, stop: signal.Signals, extra=()) -> tuple[float, float, int, str]:
    """Start a long ``warptex fit`` on 2 ranks, send rank 1 ``stop`` once rank 0 reports iterations;
    return the seconds until rank 0's error line and until torchrun ended, its status and rank 0's stderr."""
    command = _torchrun("--tee=3", "-m", "warptex", "fit", "--iters", "5000", "--resolution", "32x40", "--report-every", "1", "--out", str(tmp_path / "out"), *extra)
    agent = subprocess.Popen(command, cwd=tmp_path, env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    lines, errors, started = [], [], threading.Event()

    def read(stream, into):
        for line in stream:
            into.append((time.monotonic(), line))
            if "iter " in line and "0]:" in line:
                started.set()

    readers = [threading.Thread(target=read, args=(s, into), daemon=True) for s, into in ((agent.stdout, lines), (agent.stderr, errors))]
    for t in readers:
        t.start()
    try:
        assert started.wait(240), "rank 0 never reported an iteration:\n" + "".join(l for _, l in errors)[-3000:]
        victim = _rank_pid(agent.pid, 1)
        os.kill(victim, stop)
        stopped = time.monotonic()
        deadline = stopped + 60
        while time.monotonic() < deadline and not any("0]:warptex: " in l for _, l in errors):
            time.sleep(0.2)
        if stop == signal.SIGSTOP:
            os.kill(victim, signal.SIGCONT)  # as a hung machine that comes back: torchrun may then stop it
        status = agent.wait(timeout=max(1.0, deadline - time.monotonic()) + 30)
    finally:
        if agent.poll() is None:
            agent.kill()
            agent.wait()
    for t in readers:
        t.join(10)
    said = [(t, l) for t, l in errors if "0]:warptex: " in l]
    assert said, "rank 0 said nothing:\n" + "".join(l for _, l in errors)[-3000:]
    return said[0][0] - stopped, time.monotonic() - stopped, status, said[0][1]


@needs_gloo
@linux
def test_a_rank_killed_mid_fit_fails_the_run_at_once_and_keeps_the_previous_outputs(tmp_path):
    before = _previous_set(tmp_path / "out")
    error_after, ended_after, status, said = _fit_and_stop_rank_1(tmp_path, signal.SIGKILL)
    assert status != 0 and error_after < 60 and ended_after < 60, (status, error_after, ended_after)
    # Rank 0 sees the closed connection, or torchrun's SIGTERM, whichever comes first.
    assert "another rank of the process group died" in said or "terminated (SIGTERM: another process of the job failed" in said, said
    assert {p.name: (p.read_bytes(), p.stat().st_mtime_ns) for p in (tmp_path / "out").iterdir()} == before


@needs_gloo
@linux
def test_a_rank_that_stops_answering_fails_the_run_after_the_timeout(tmp_path):
    before = _previous_set(tmp_path / "out")
    error_after, ended_after, status, said = _fit_and_stop_rank_1(tmp_path, signal.SIGSTOP, ["--dist-timeout", "5"])
    assert status != 0 and 4 < error_after < 30 and ended_after < 60, (status, error_after, ended_after)
    assert "stopped answering within the group's timeout" in said and "Timed out" in said, said
    assert {p.name: (p.read_bytes(), p.stat().st_mtime_ns) for p in (tmp_path / "out").iterdir()} == before


def test_ranks_checking_one_new_output_folder_at_once_all_pass(tmp_path, monkeypatch):
    """Every rank checks the output folder before the fit; where it is new, each creates it to
    probe it and removes it again. A rank whose folder another removed between its mkdir and its
    probe (CI saw ``cannot write into the output folder 'out/fit': No such file or directory``)
    tries again rather than failing the job."""
    from warptex import _output

    out = tmp_path / "out" / "fit"
    real_touch = Path.touch
    removed = []

    def touch(self, *args, **kwargs):
        if self.name.endswith(".probe") and not removed:  # the other rank's clean-up, just before our probe
            removed.append(self.parent)
            self.parent.rmdir()
            self.parent.parent.rmdir()
        return real_touch(self, *args, **kwargs)

    monkeypatch.setattr(Path, "touch", touch)
    assert _output.check_output_folder("run_fit", out) == out
    assert removed == [out] and not (tmp_path / "out").exists()  # checked, and left as found

    errors = []  # 8 checkers at once, 20 times (CI once caught one seeing the folder vanish between two looks)
    for round_ in range(20):
        threads = [threading.Thread(target=_record, args=(errors, _output.check_output_folder, "run_fit", tmp_path / f"again{round_}" / "fit")) for _ in range(8)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
    assert errors == []


def _record(errors: list, run, *args) -> None:
    try:
        run(*args)
    except OSError as err:
        errors.append(err)


@pytest.mark.skipif(sys.platform == "win32", reason="sends itself SIGTERM, which Windows cannot catch")
def test_a_sigterm_while_a_failed_rank_says_why_does_not_replace_its_line(monkeypatch, capsys):
    """torchrun sends SIGTERM to every rank once one fails: it may come while this rank is still
    reporting its own failure (stop 55's CI). The rank's one line must come out all the same."""
    from warptex.apps import cli
    from warptex.apps.distributed import _terminate
    from warptex.fit.distributed import DistributedError

    def fail(args):
        raise DistributedError("another rank of the process group died")

    def one_line(err):
        os.kill(os.getpid(), signal.SIGTERM)  # arrives while the line is being made
        time.sleep(0.05)
        return str(err)

    previous = signal.signal(signal.SIGTERM, _terminate)
    try:
        monkeypatch.setattr(cli, "_run", fail)
        monkeypatch.setattr(cli, "_one_line", one_line)
        assert cli_main(["fit", "--iters", "1", "--out", "unused"]) == 1
    finally:
        signal.signal(signal.SIGTERM, previous)
    assert capsys.readouterr().err == "warptex: error: another rank of the process group died\n"


@needs_gloo
@pytest.mark.skipif(sys.platform == "win32", reason="sends SIGINT")
def test_ctrl_c_while_a_rank_waits_for_the_others_to_start_stops_it_at_once(tmp_path):
    """Rank 0 of two, the other never started: it waits in torch.distributed's rendezvous, in
    native code, for up to 10 minutes, and a Ctrl-C meanwhile was held until then (issue 50
    item 8). It now ends the rank at once with the one line."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    env = {**_env(), "WORLD_SIZE": "2", "RANK": "0", "LOCAL_RANK": "0", "LOCAL_WORLD_SIZE": "1", "MASTER_ADDR": "127.0.0.1", "MASTER_PORT": str(port)}
    rank = subprocess.Popen([sys.executable, "-m", "warptex", "fit", "--iters", "2", "--resolution", "24x32", "--out", str(tmp_path / "out")], cwd=tmp_path, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:  # rank 0 serves the rendezvous's store once it waits there
            with socket.socket() as s:
                if s.connect_ex(("127.0.0.1", port)) == 0:
                    break
            assert rank.poll() is None, rank.communicate()
            time.sleep(0.2)
        else:
            raise AssertionError("rank 0 never reached the rendezvous")
        time.sleep(1.0)
        rank.send_signal(signal.SIGINT)
        sent = time.monotonic()
        _, err = rank.communicate(timeout=60)
    finally:
        if rank.poll() is None:
            rank.kill()
            rank.wait()
    assert rank.returncode == 130 and time.monotonic() - sent < 5.0, (rank.returncode, time.monotonic() - sent, err[-2000:])
    assert err.strip().splitlines()[-1] == "warptex: interrupted; no files were written", err[-2000:]
    assert not (tmp_path / "out").exists()
