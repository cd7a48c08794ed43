"""Nothing mmexec starts listens beyond loopback unless the user gives an address: the
local Ray instance of ``mmexec campaign --ray`` and the protocol fakes of ``mmexec hw
fake DEVICE`` (issue 9 item 14).

What is asserted is what the kernel reports: the listening TCP sockets (``/proc/net/tcp``
and ``tcp6``) held by the process and all its descendants, so a server started by a
child (the UR fake's stub process, Ray's GCS, raylet and workers) is seen too."""

from __future__ import annotations

import ipaddress
import os
import selectors
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from mmexec.executive.campaign.pools import LOOPBACK, RAY_SINGLE_MACHINE_ENV, import_ray, ray_init

HW = [sys.executable, "-m", "mmexec.drivers.hwcli"]
TCP_LISTEN = "0A"


def descendants(pid: int) -> set[int]:
    """``pid`` and every process below it, from each process's parent in /proc/PID/stat."""
    children: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:  # the process ended while the table was read: not ours to count
            continue
        ppid = int(stat.rsplit(")", 1)[1].split()[1])
        children.setdefault(ppid, []).append(int(entry.name))
    found, todo = set(), [pid]
    while todo:
        p = todo.pop()
        found.add(p)
        todo.extend(children.get(p, []))
    return found


def socket_inodes(pids: set[int]) -> set[str]:
    """The inodes of the sockets the processes ``pids`` hold open."""
    inodes = set()
    for pid in pids:
        fd_dir = Path(f"/proc/{pid}/fd")
        try:
            fds = list(fd_dir.iterdir())
        except OSError:  # the process ended meanwhile
            continue
        for fd in fds:
            try:
                target = os.readlink(fd)
            except OSError:  # the descriptor was closed meanwhile
                continue
            if target.startswith("socket:["):
                inodes.add(target[len("socket:["):-1])
    return inodes


def kernel_address(hex_address: str) -> str:
    """An address of /proc/net/tcp{,6}: 32-bit words in host byte order, as text."""
    raw = bytes.fromhex(hex_address)
    words = b"".join(int.from_bytes(raw[i:i + 4], "big").to_bytes(4, sys.byteorder) for i in range(0, len(raw), 4))
    return socket.inet_ntop(socket.AF_INET if len(raw) == 4 else socket.AF_INET6, words)


def listening(pid: int) -> list[tuple[str, int]]:
    """(address, port) of every TCP socket listening in ``pid`` or its descendants."""
    inodes = socket_inodes(descendants(pid))
    found = []
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        for line in Path(table).read_text().splitlines()[1:]:
            cols = line.split()
            local, state, inode = cols[1], cols[3], cols[9]
            if state == TCP_LISTEN and inode in inodes:
                host, port = local.rsplit(":", 1)
                found.append((kernel_address(host), int(port, 16)))
    return found


def is_loopback(address: str) -> bool:
    ip = ipaddress.ip_address(address)
    mapped = getattr(ip, "ipv4_mapped", None)
    return ip.is_loopback or (mapped is not None and mapped.is_loopback)


def test_kernel_address_decoding() -> None:
    with socket.create_server(("127.0.0.1", 0)) as srv:
        port = srv.getsockname()[1]
        assert ("127.0.0.1", port) in listening(os.getpid())
    assert kernel_address("0100007F") == "127.0.0.1" and kernel_address("00000000") == "0.0.0.0"
    assert not is_loopback("0.0.0.0") and not is_loopback("::") and is_loopback("::ffff:127.0.0.1")


# --------------------------------------------------------------------------- hw fake


@contextmanager
def fake_process(*args: str, timeout: float = 30.0) -> Iterator[tuple[subprocess.Popen[str], str]]:
    """Run ``mmexec hw fake ARGS`` with its defaults; yield it and the address or port it
    prints (a bounded wait); SIGINT at exit."""
    proc = subprocess.Popen([*HW, "fake", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=dict(os.environ, PYTHONUNBUFFERED="1"))
    try:
        assert proc.stdout is not None
        with selectors.DefaultSelector() as sel:
            sel.register(proc.stdout, selectors.EVENT_READ)
            deadline = time.monotonic() + timeout
            while not sel.select(0.1):
                assert proc.poll() is None, f"fake exited: {proc.stderr.read() if proc.stderr else ''}"
                assert time.monotonic() < deadline, f"fake {args} printed nothing within {timeout} s"
        yield proc, proc.stdout.readline().strip()
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=5)


@pytest.mark.parametrize("args", [("ur", "--port", "0"), ("robotiq", "--urcap")], ids=["ur", "robotiq-urcap"])
def test_socket_fakes_listen_on_loopback_by_default(args: tuple[str, ...]) -> None:
    """``--port 0`` only so stubs of other tests on 30004 do not collide; the host is the default."""
    with fake_process(*args) as (proc, printed):
        host, _, port = printed.rpartition(":")
        assert host == LOOPBACK
        # the UR fake prints once its stub process is listening; the URCap fake before serving
        assert listening(proc.pid) == [(LOOPBACK, int(port))]


@pytest.mark.parametrize("device", ["kobuki", "dynamixel", "robotiq"])
def test_serial_fakes_listen_nowhere(device: str) -> None:
    with fake_process(device) as (proc, printed):
        assert printed.startswith("/dev/pts/")
        assert listening(proc.pid) == []


# --------------------------------------------------------------------------- campaign --ray


def test_a_local_ray_instance_listens_on_loopback_only() -> None:
    """What ``mmexec campaign --ray`` (no address) starts: on Linux Ray's default is the
    machine's routable address with every server on all interfaces."""
    def worker_pid() -> int:  # nested: Ray ships it by value, the worker cannot import this module
        return os.getpid()

    ray = import_ray(local=True)
    assert ray_init(ray, 1, "")
    try:
        assert ray.get(ray.remote(num_cpus=1)(worker_pid).remote()) != os.getpid()  # a worker is up
        addresses = listening(os.getpid())
        assert len(addresses) >= 2, addresses  # at least the GCS and the raylet
        assert [a for a in addresses if not is_loopback(a[0])] == []
    finally:
        ray.shutdown()


def test_ray_imported_before_loopback_was_selected_is_refused() -> None:
    """Ray read its cluster mode when it was imported: a local instance would then listen
    on the routable address, so it is shut down again and the campaign stops in one line."""
    script = (
        "import ray\n"
        "from mmexec.config.yamlload import InputError\n"
        "from mmexec.executive.campaign.pools import import_ray, ray_init\n"
        "try:\n"
        "    ray_init(import_ray(local=True), 1, '')\n"
        "except InputError as e:\n"
        "    print(e)\n"
        "    print('initialized:', ray.is_initialized())\n"
    )
    env = {k: v for k, v in os.environ.items() if k != RAY_SINGLE_MACHINE_ENV}
    res = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env, timeout=180,
                         check=False)
    assert res.returncode == 0, res.stderr
    message, state = res.stdout.splitlines()
    assert message.startswith("--ray: a local Ray instance would listen on ") and f"not {LOOPBACK}" in message
    assert state == "initialized: False"
