"""Studies on Dask: the same JSON on one worker, two, and a real scheduler with its workers.

The real cluster is ``dask scheduler`` and two ``dask worker`` processes started here on
loopback on ports the system chose; one test kills a worker in the middle of a study.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import socket
import subprocess
import sys
import threading
import warnings
from collections.abc import Iterator
from pathlib import Path

import pytest
import yaml
from cli_runner import invoke as gcs_invoke

from gcs.app import study_cluster
from gcs.app.study_chunks import (
    build_plan,
    definition_document,
    open_output,
    run_study_chunks,
    study_document,
    summarise_study,
)
from gcs.app.study_cluster import Cluster, connect
from gcs.io.study import load_study

BIN = Path(sys.executable).parent
STUDY = {
    "name": "tiny",
    "profile": "antx",
    "trajectory": "eight-short",
    "seed": 5,
    "plants": 4,
    "iterations": 2,
    "chunk_plants": 1,
    "steady_trials": 1,
    "uncertainty": {"levels": [0.3], "noise_std_m": 0.01, "disturbance_rms_m": 0.05},
    "grid": {"wdu": [0.01, 0.1]},
}


@contextlib.contextmanager
def a_closed_port() -> Iterator[int]:
    """A loopback port held bound but not listening while the block runs: nothing can accept
    a connection there, so a client is refused at once."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        yield s.getsockname()[1]


def scheduler_address(scheduler: subprocess.Popen) -> str:
    """The address ``dask scheduler --port 0`` says it listens on (its log on stderr); the rest
    of the log is drained in a thread so that the scheduler never blocks on a full pipe."""
    assert scheduler.stderr is not None
    for line in scheduler.stderr:
        if "Scheduler at:" in line:
            threading.Thread(target=scheduler.stderr.read, daemon=True).start()
            return line.split("Scheduler at:", 1)[1].strip()
    raise AssertionError(f"dask scheduler ended (code {scheduler.wait()}) before listening")


@pytest.fixture(scope="module")
def study_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("study") / "tiny.yaml"
    path.write_text(yaml.safe_dump(STUDY))
    return path


def run_cli(*args: str) -> tuple[int, str]:
    result = gcs_invoke(list(args), env={"COLUMNS": "120"})
    return result.exit_code, result.output


@pytest.fixture(scope="module")
def reference(study_file: Path, tmp_path_factory: pytest.TempPathFactory) -> bytes:
    """study.json of the study on a LocalCluster of one worker."""
    out = tmp_path_factory.mktemp("one") / "out"
    code, output = run_cli("study", str(study_file), "--out", str(out), "--workers", "1")
    assert code == 0, output
    assert "recommended:" in output
    return (out / "study.json").read_bytes()


@pytest.mark.processes
def test_two_local_workers_give_the_json_of_one(
    study_file: Path, reference: bytes, tmp_path: Path
) -> None:
    code, output = run_cli("study", str(study_file), "--out", str(tmp_path / "o"), "--workers", "2")
    assert code == 0, output
    assert (tmp_path / "o" / "study.json").read_bytes() == reference
    data = json.loads(reference)
    assert data["definition"]["seed"] == 5 and data["definition"]["gcs_version"]
    assert len(data["results"]) == 2 and len(data["results"][0]["plants_results"]) == 4


@pytest.mark.processes
def test_a_local_cluster_serves_http_on_loopback_on_a_free_port_and_says_nothing() -> None:
    """The scheduler of a LocalCluster serves a small HTTP interface even without its dashboard;
    Dask's default port 8787 would be taken by a second study (or the user's own cluster) and
    Dask would then warn on the terminal. gcs's asks for a free port on loopback: with 8787 held
    here, nothing is said."""
    held = socket.socket()
    try:
        held.bind(("127.0.0.1", 8787))
        held.listen()
    except OSError:
        pass  # another program has it: held all the same
    with held, warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        with connect(Cluster(workers=1)) as client:
            http = client.cluster.scheduler.http_server
            assert (http.address, client.submit(sum, [1, 2]).result()) == ("127.0.0.1", 3)
            assert http.port != 8787
    assert not [str(w.message) for w in said if "8787" in str(w.message)]


@pytest.fixture
def real_cluster(tmp_path: Path) -> Iterator[tuple[str, list[subprocess.Popen]]]:
    """``dask scheduler`` and two ``dask worker`` processes on loopback, on ports the system
    chose (``--port 0``; the scheduler says which)."""
    env = os.environ | {"OPENBLAS_NUM_THREADS": "1"}
    common = {"env": env, "stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
    scheduler = subprocess.Popen(
        [str(BIN / "dask"), "scheduler", "--host", "127.0.0.1", "--port", "0",
         "--no-dashboard"], start_new_session=True, env=env, stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    address = scheduler_address(scheduler)
    workers = [
        subprocess.Popen(
            [
                str(BIN / "dask"),
                "worker",
                address,
                "--nthreads",
                "1",
                "--no-dashboard",
                "--host",
                "127.0.0.1",
                "--name",
                f"w{i}",
            ],
            start_new_session=True,
            **common,
        )  # fmt: skip
        for i in range(2)
    ]
    try:
        from distributed import Client

        with Client(address, timeout=60) as client:
            client.wait_for_workers(2, timeout=60)
        yield address, workers
    finally:
        for p in [*workers, scheduler]:
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGTERM)
        for p in [*workers, scheduler]:
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait()


@pytest.mark.processes
def test_a_real_scheduler_and_two_workers_give_the_same_json(
    study_file: Path, reference: bytes, real_cluster: tuple[str, list], tmp_path: Path
) -> None:
    address, _ = real_cluster
    out = tmp_path / "o"
    code, output = run_cli("study", str(study_file), "--out", str(out), "--scheduler", address)
    assert code == 0, output
    assert (out / "study.json").read_bytes() == reference


@pytest.mark.processes
def test_a_worker_killed_mid_study_changes_nothing(
    study_file: Path, reference: bytes, real_cluster: tuple[str, list], tmp_path: Path
) -> None:
    address, workers = real_cluster
    spec = load_study(study_file)
    plan = build_plan(spec)
    document = definition_document(spec, plan)
    output = open_output(tmp_path / "o", document)
    seen: list[int] = []

    def progress(done: int, total: int) -> None:
        seen.append(done)
        if done == 1:  # the first chunk is in: the others are queued on both workers
            os.killpg(workers[0].pid, signal.SIGKILL)

    with connect(Cluster(scheduler=address)) as client:
        results = run_study_chunks(plan, output, client, progress)
    assert workers[0].wait(timeout=20) == -signal.SIGKILL
    assert seen[-1] == len(plan.settings) * plan.chunks
    outcome = summarise_study(plan, results)
    text = json.dumps(study_document(document, plan, outcome), indent=1) + "\n"
    assert text.encode() == reference


@pytest.mark.processes
def test_an_interrupted_study_resumes_the_missing_chunks(
    study_file: Path, reference: bytes, tmp_path: Path
) -> None:
    out = tmp_path / "o"
    code, output = run_cli("study", str(study_file), "--out", str(out), "--workers", "0")
    assert code == 0, output
    kept = sorted((out / "chunks").iterdir())
    for p in kept[1::2]:  # as if the study had stopped with half of its chunks
        p.unlink()
    before = {p.name: p.read_bytes() for p in (out / "chunks").iterdir()}
    (out / "study.json").unlink()
    code, output = run_cli("study", str(study_file), "--out", str(out), "--workers", "0")
    assert code == 0, output
    assert f"resuming: {len(before)} of {len(kept)} chunks" in " ".join(output.split())
    assert {
        p.name: p.read_bytes() for p in (out / "chunks").iterdir() if p.name in before
    } == before
    assert len(list((out / "chunks").iterdir())) == len(kept)


def test_another_study_in_the_same_directory_is_refused(study_file: Path, tmp_path: Path) -> None:
    out = tmp_path / "o"
    code, _ = run_cli("study", str(study_file), "--out", str(out), "--workers", "0")
    assert code == 0
    other = tmp_path / "other.yaml"
    other.write_text(yaml.safe_dump(STUDY | {"seed": 6}))
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    code, output = run_cli("study", str(other), "--out", str(out), "--workers", "0")
    assert code == 2 and "holds another study" in output and len(output.splitlines()) == 1
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before


def test_an_unreachable_scheduler_is_one_line(
    study_file: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(study_cluster, "CONNECT_TIMEOUT_S", 1.0)
    with a_closed_port() as port:
        address = f"tcp://127.0.0.1:{port}"
        out = tmp_path / "o"
        code, output = run_cli("study", str(study_file), "--out", str(out), "--scheduler", address)
        assert code == 2, output
        assert len(output.strip().splitlines()) == 1
        assert "unreachable" in output and address in output
        assert not out.exists()
        code, output = run_cli(
            "montecarlo", "--plants", "2", "--repeats", "1", "--scheduler", address
        )
    assert code == 2 and "unreachable" in output and len(output.strip().splitlines()) == 1


def test_a_short_studys_here_by_default_with_the_json_of_workers_0(
    study_file: Path, tmp_path: Path
) -> None:
    documents = {}
    for name, extra in (("default", []), ("0", ["--workers", "0"])):
        out = tmp_path / name
        code, output = run_cli("study", str(study_file), "--out", str(out), *extra)
        assert code == 0, output
        said = " ".join(output.split())
        if name == "default":
            assert "in this process: the study is short (est. " in said
        else:
            assert "in this process (as asked)" in said
        documents[name] = (out / "study.json").read_bytes()
    assert documents["default"] == documents["0"]
