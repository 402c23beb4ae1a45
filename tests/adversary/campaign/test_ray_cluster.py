"""A real two-node Ray cluster on this machine (a head and a second node on loopback): the tiny
campaign runs on it with `--backend ray --address`, the second node is killed mid-campaign, and
the campaign still records every job exactly once, with results equal to a local run. The log
names the lost node and the retried jobs. Run by `make test-cluster` (marker `cluster`)."""

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from adversary.report.page import make_report
from tests.adversary.conftest import TINY

pytestmark = pytest.mark.cluster
ROOT = Path(__file__).resolve().parents[3]
RAY = Path(sys.executable).with_name("ray")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _env() -> dict:
    # Token authentication off: a token file in ~/.ray from another use must not lock us out.
    return {**os.environ, "RAY_AUTH_MODE": "disabled", "OMP_NUM_THREADS": "1",
            "RAY_USAGE_STATS_ENABLED": "0"}


def _start_node(args: list[str], log: Path) -> subprocess.Popen:
    """`ray start ... --block` in a session of its own, so that killing its process group kills
    the node (raylet, object store, workers) as a machine failure would."""
    return subprocess.Popen([str(RAY), "start", *args, "--node-ip-address=127.0.0.1",
                             "--disable-usage-stats", "--block"],
                            stdout=log.open("w"), stderr=subprocess.STDOUT, env=_env(),
                            start_new_session=True)


def _alive_nodes(address: str) -> int:
    probe = ("import ray; ray.init(address=%r, log_to_driver=False); "
             "print(sum(n['Alive'] for n in ray.nodes()))" % address)
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                          env=_env(), timeout=120, check=False)
    return int(done.stdout.strip().splitlines()[-1]) if done.returncode == 0 else 0


def _running_a_task(node: subprocess.Popen) -> bool:
    """Whether a worker of `node` (its process group) is executing a task: Ray titles a busy
    worker process "ray::<task>" and an idle one "ray::IDLE" (Linux /proc)."""
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            title = (entry / "cmdline").read_bytes().split(b"\0")[0].decode(errors="replace")
            if title.startswith("ray::") and "IDLE" not in title and os.getpgid(int(entry.name)) == node.pid:
                return True
        except (OSError, ProcessLookupError):
            continue
    return False


def _kill(process: subprocess.Popen) -> None:
    try:
        os.killpg(process.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    process.wait(timeout=30)


@pytest.fixture()
def cluster(tmp_path):
    pytest.importorskip("ray")
    port = _free_port()
    address = f"127.0.0.1:{port}"
    head = _start_node(["--head", f"--port={port}", "--num-cpus=1", "--include-dashboard=false"],
                       tmp_path / "head.log")
    second = None
    try:
        deadline = time.time() + 120
        while _alive_nodes(address) < 1:
            assert time.time() < deadline, (tmp_path / "head.log").read_text()[-2000:]
            time.sleep(1)
        second = _start_node([f"--address={address}", "--num-cpus=2"], tmp_path / "second.log")
        while _alive_nodes(address) < 2:
            assert time.time() < deadline, (tmp_path / "second.log").read_text()[-2000:]
            time.sleep(1)
        yield address, second
    finally:
        if second is not None:
            _kill(second)
        _kill(head)
        subprocess.run([str(RAY), "stop", "--force"], capture_output=True, env=_env(), check=False)


def test_a_campaign_survives_the_loss_of_a_node(cluster, tiny_campaign, tmp_path):
    address, second = cluster
    config = tmp_path / "tiny.yaml"
    config.write_text(yaml.safe_dump(TINY))
    out = tmp_path / "stress"
    argv = [sys.executable, "-m", "adversary", "stress-test", "--config", str(config), "--out",
            str(out), "--backend", "ray", "--address", address, "--workers", "3", "--quiet"]
    campaign = subprocess.Popen(argv, cwd=ROOT, env=_env(), stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True)
    records = out / "records"
    deadline = time.time() + 600
    # The second node dies mid-campaign while it is running a job (waiting for a number of
    # finished records instead left it idle at the kill in some runs: nothing lost, nothing to
    # retry).
    while not (records.exists() and len(list(records.glob("*.json"))) >= 1 and _running_a_task(second)):
        assert campaign.poll() is None, campaign.communicate()
        assert time.time() < deadline
        time.sleep(0.05)
    finished_before = len(list(records.glob("*.json")))
    _kill(second)
    stdout, stderr = campaign.communicate(timeout=900)
    assert campaign.returncode == 0, stderr[-3000:]
    assert finished_before < 12, "the campaign finished before the node was killed"
    log = [line for line in stderr.splitlines() if line.startswith("ray: ")]
    print("\n".join(log))                          # shown by make test-cluster (-rP)
    retried = [line for line in log if "retrying" in line]
    assert retried, stderr[-3000:]
    assert all("NodeDiedError" in line and "node ID" in line for line in retried)

    jobs = [json.loads(p.read_text()) for p in sorted(records.glob("*.json"))]
    ids = [job["job_id"] for job in jobs]
    assert len(ids) == 12 and len(set(ids)) == 12          # every job once
    assert all(job["status"] == "ok" for job in jobs)
    on_cluster = make_report(out, tmp_path / "report_cluster")["results"]
    local = make_report(tiny_campaign, tmp_path / "report_local")["results"]
    assert on_cluster == local
