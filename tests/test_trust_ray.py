"""Issue 37 (trust), Ray: a token left in the home folder meets a cluster without tokens (item 12), and the
local clusters twisted starts listen on loopback only (item 13).

Every cluster here is real (Ray's own multi-node test utility, or ``ray_cluster`` as the CLI starts one)
and runs in a child process with its own home folder and Ray temporary folder (``RAY_TMPDIR``), so that
neither the token Ray writes nor the "current cluster" file it leaves is seen by anything else.
"""

from __future__ import annotations

import ipaddress
import json
import os
import shutil
import socket
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest
from sqlalchemy import func, select

from twisted.store import Transition, open_store

ray = pytest.importorskip("ray")

from twisted.distributed import cluster_uses_tokens  # noqa: E402 - after the skip: needs ray

pytestmark = pytest.mark.ray
REPO = Path(__file__).resolve().parents[1]

# A head node of 1 CPU started by Ray's test utility (no dashboard); prints its address, stops when its
# stdin closes. argv[1]: RAY_AUTH_MODE of the cluster ("disabled" or "token").
CLUSTER = """
import os, sys
os.environ["RAY_AUTH_MODE"] = sys.argv[1]
from ray.cluster_utils import Cluster
cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1, "include_dashboard": False})
print("ADDRESS", cluster.address, flush=True)
sys.stdin.read()
cluster.shutdown()
"""


@pytest.fixture
def home() -> Iterator[dict[str, str]]:
    """The environment of a user with a fresh home folder and Ray temporary folder (short paths: Ray's
    socket names must fit 107 bytes)."""
    folder = Path(tempfile.mkdtemp(prefix="twr-", dir="/tmp"))
    (folder / "home").mkdir()
    env = {k: v for k, v in os.environ.items() if not k.startswith(("RAY_ADDRESS", "RAY_AUTH"))}
    env.update(HOME=str(folder / "home"), RAY_TMPDIR=str(folder / "ray"), COLUMNS="1000")
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH", "")]))
    yield env
    shutil.rmtree(folder, ignore_errors=True)


def _token_file(env: dict[str, str], token: str) -> Path:
    """Where Ray keeps its token (Path.home() / ".ray" / "auth_token", see twisted.distributed)."""
    path = Path(env["HOME"]) / ".ray" / "auth_token"
    path.parent.mkdir(exist_ok=True)
    path.write_text(token)
    return path


class _Cluster:
    def __init__(self, env: dict[str, str], auth_mode: str) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-c", CLUSTER, auth_mode],
            env=env,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            text=True,
        )
        assert self.proc.stdout is not None
        line = self.proc.stdout.readline()
        assert line.startswith("ADDRESS "), f"the cluster did not start: {line!r}"
        self.address = line.split()[1]

    def stop(self) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.close()
        try:
            self.proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


@pytest.fixture
def cluster_without_tokens(home: dict[str, str]) -> Iterator[_Cluster]:
    cluster = _Cluster(home, "disabled")
    yield cluster
    cluster.stop()


def _cli(env: dict[str, str], *args: str, timeout: float = 300) -> tuple[int, str, str]:
    done = subprocess.run(
        [sys.executable, "-m", "cli.main", *args],
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout,
    )
    return done.returncode, " ".join((done.stdout + done.stderr).split()), done.stderr


# --- 12. a token in the home folder, a cluster without tokens -----------------------------------------------


def test_a_token_left_at_home_meets_a_cluster_without_tokens(
    cluster_without_tokens: _Cluster, home: dict[str, str], tmp_path: Path
) -> None:
    """Before: with ~/.ray/auth_token left by an earlier `ray start` (or any local cluster: Ray writes one
    when it starts a cluster), `collect --ray ADDRESS` to a cluster without tokens connected, then every
    worker died at once and the run failed with "every worker died" (nothing said why). Now it exits 2
    saying what to do; and once told (RAY_AUTH_MODE=disabled) it collects on that cluster."""
    address = cluster_without_tokens.address
    assert cluster_uses_tokens(address) is False
    token = _token_file(home, "0123456789abcdef0123456789abcdef")
    url = f"sqlite:///{tmp_path / 'ray.db'}"
    collect = ["--db", url, "collect", "--hours", "0.01", "--max-kept", "1", "--seed", "3", "--ray", address]
    code, out, stderr = _cli(home, *collect)
    assert code == 2, out[-2000:]
    assert "Traceback" not in stderr
    assert "does not use token authentication" in out and "RAY_AUTH_MODE=disabled" in out, out
    assert str(token) in out, "names the file it found"
    code, out, stderr = _cli({**home, "RAY_AUTH_MODE": "disabled"}, *collect)
    assert code == 0, out[-3000:]
    with open_store(url) as store, store.session() as session:
        assert session.scalar(select(func.count()).select_from(Transition)) >= 1


def test_the_probe_tells_a_cluster_with_tokens(home: dict[str, str]) -> None:
    _token_file(home, "fedcba9876543210fedcba9876543210")  # the cluster's own token
    cluster = _Cluster(home, "token")
    try:
        assert cluster_uses_tokens(cluster.address) is True
    finally:
        cluster.stop()


def test_the_probe_does_not_guess() -> None:
    assert cluster_uses_tokens("ray://127.0.0.1:10001") is None  # Ray Client: not asked
    with socket.socket() as free:
        free.bind(("127.0.0.1", 0))
        port = free.getsockname()[1]
    assert cluster_uses_tokens(f"127.0.0.1:{port}") is None  # nobody listens there


# --- 13. the local cluster listens on loopback only ---------------------------------------------------------

# Starts a cluster as `twisted collect --ray` does without an address (ray_cluster(None): none runs here,
# so a new one), runs an actor, then prints every TCP socket that a process of its tree listens on.
LOCAL_CLUSTER = """
import json, os, socket, sys, time
from twisted.distributed import ray_cluster

def listening_sockets():
    by_inode = {}
    for table, family in (("tcp", socket.AF_INET), ("tcp6", socket.AF_INET6)):
        with open(f"/proc/net/{table}") as fh:
            next(fh)
            for line in fh:
                fields = line.split()
                if fields[3] != "0A":  # LISTEN
                    continue
                address, port = fields[1].split(":")
                raw = bytes.fromhex(address)
                raw = b"".join(raw[i : i + 4][::-1] for i in range(0, len(raw), 4))  # host-order words
                by_inode[fields[9]] = (socket.inet_ntop(family, raw), int(port, 16))
    children = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                parent = int(open(f"/proc/{entry}/stat").read().rsplit(")", 1)[1].split()[1])
            except OSError:
                continue
            children.setdefault(parent, []).append(int(entry))
    tree, todo = [], [os.getpid()]
    while todo:
        pid = todo.pop()
        tree.append(pid)
        todo += children.get(pid, [])
    found = []
    for pid in tree:
        try:
            name = open(f"/proc/{pid}/comm").read().strip()
            links = [os.readlink(f"/proc/{pid}/fd/{fd}") for fd in os.listdir(f"/proc/{pid}/fd")]
        except OSError:
            continue
        for link in links:
            if link.startswith("socket:[") and link[8:-1] in by_inode:
                found.append([*by_inode[link[8:-1]], name])
    return found

with ray_cluster(None) as ray:
    @ray.remote(num_cpus=1)
    class Probe:
        def pid(self):
            return os.getpid()

    ray.get(Probe.remote().pid.remote())
    time.sleep(2)  # the agents bind their ports while the first worker starts
    print("LISTENING " + json.dumps(listening_sockets()), flush=True)
"""


def _loopback(address: str) -> bool:
    ip = ipaddress.ip_address(address)
    mapped = getattr(ip, "ipv4_mapped", None)
    return (mapped or ip).is_loopback


@pytest.mark.skipif(not Path("/proc/net/tcp").exists(), reason="reads the sockets from /proc (Linux)")
def test_the_local_cluster_listens_on_loopback_only(home: dict[str, str]) -> None:
    """Before: a cluster started the way the project starts one (ray.init without an address) had its GCS,
    raylet, workers and agents listening on every interface (`ss -ltnp`: `*:port` and the machine's own
    address). Now its node address is 127.0.0.1 and so is every port its processes listen on."""
    done = subprocess.run(
        [sys.executable, "-c", LOCAL_CLUSTER], env=home, capture_output=True, text=True, timeout=300, cwd=REPO
    )
    line = next((x for x in done.stdout.splitlines() if x.startswith("LISTENING ")), None)
    assert line is not None, done.stderr[-3000:]
    listening = [tuple(x) for x in json.loads(line.split(" ", 1)[1])]
    names = {name for _, _, name in listening}
    assert {"gcs_server", "raylet"} <= names, listening  # the cluster's own servers were seen
    exposed = [x for x in listening if not _loopback(x[0])]
    assert not exposed, f"listening beyond loopback: {exposed}"
