"""``mmexec serve`` as a process: the listening line, the token off loopback (generated or
from the config's file), a signal's safety contract, the API's stop, and bad --bind."""

from __future__ import annotations

import os
import select
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx2
import pytest

from mmexec.executive.eventlog import read_log

EXE = Path(sys.executable).with_name("mmexec")
ROOT = Path(__file__).resolve().parents[2]
MOCK = ROOT / "config" / "mock.yaml"
MISSIONS = Path(__file__).resolve().parent / "missions"
#: [wall s] generous bound for a loaded machine to start the command or reach a state
LIMIT = 90.0


class Proc:
    def __init__(self, *args: str, cwd: Path) -> None:
        self.cwd = cwd
        self.p = subprocess.Popen([str(EXE), "serve", *args], cwd=cwd, stdout=subprocess.PIPE,
                                  stderr=subprocess.PIPE, stdin=subprocess.DEVNULL, text=True)
        self.lines: list[str] = []
        self._partial = b""

    def line(self, prefix: str) -> str:
        """The first stdout line starting with ``prefix`` (waits for it)."""
        assert self.p.stdout is not None
        fd = self.p.stdout.fileno()
        deadline = time.monotonic() + LIMIT
        while True:
            for line in self.lines:
                if line.startswith(prefix):
                    return line
            ready, _, _ = select.select([fd], [], [], max(0.0, deadline - time.monotonic()))
            if not ready:
                raise AssertionError(f"no {prefix!r} line within {LIMIT} s")
            chunk = os.read(fd, 65536)
            if not chunk:
                raise AssertionError(f"exited {self.p.wait()} before a {prefix!r} line: {self.p.stderr.read()}")  # type: ignore[union-attr]
            self._partial += chunk
            *done, self._partial = self._partial.split(b"\n")
            self.lines += [d.decode() for d in done]

    def url(self) -> str:
        line = self.line("mmexec serve:")
        return line.split(": ", 2)[2].split("/api/status", 1)[0]

    def wait(self) -> int:
        return self.p.wait(LIMIT)


@pytest.fixture
def procs() -> Iterator[list[Proc]]:
    started: list[Proc] = []
    yield started
    for proc in started:
        if proc.p.poll() is None:
            proc.p.kill()
            proc.p.wait()
        for stream in (proc.p.stdout, proc.p.stderr):
            if stream is not None:
                stream.close()


def _until(fn: Any) -> Any:
    deadline = time.monotonic() + LIMIT
    while time.monotonic() < deadline:
        value = fn()
        if value:
            return value
        time.sleep(0.02)
    raise AssertionError("the service never got there")


def test_sigterm_halts_the_tree_and_ends_the_log(tmp_path: Path, procs: list[Proc]) -> None:
    proc = Proc(str(MISSIONS / "ask_confirm.yaml"), "--config", str(MOCK), "--bind", "127.0.0.1:0",
                "--log", "serve.jsonl", cwd=tmp_path)
    procs.append(proc)
    url = proc.url()
    with httpx2.Client(base_url=url) as c:
        first = c.post("/api/requests", json={"item": 1}).json()["id"]
        second = c.post("/api/requests", json={"item": 2}).json()["id"]
        _until(lambda: c.get("/api/prompts").json())
    proc.p.send_signal(signal.SIGTERM)
    assert proc.wait() == 143
    recs = read_log(tmp_path / "serve.jsonl")
    halt = next(r for r in recs if r["event"] == "halt")
    assert halt["reason"] == "interrupt" and halt["signal"] == "SIGTERM" and halt["index"] == first
    end = next(r for r in recs if r["event"] == "request_end")
    assert end["id"] == first and end["outcome"] == "interrupted" and end["reason"] == "interrupted (SIGTERM)"
    dropped = [r for r in recs if r["event"] == "request_dropped"]
    assert [(d["id"], d["reason"]) for d in dropped] == [(second, "the service was interrupted")]
    assert recs[-1]["event"] == "run_end" and recs[-1]["outcome"] == "interrupted" and recs[-1]["exit_code"] == 143
    assert any(r["event"] == "operator_prompt_closed" and r["reason"] == "cancelled" for r in recs)


def test_off_loopback_every_call_needs_the_printed_token(tmp_path: Path, procs: list[Proc]) -> None:
    proc = Proc(str(MISSIONS / "quick.yaml"), "--config", str(MOCK), "--bind", "0.0.0.0:0", "--log", "s.jsonl",
                cwd=tmp_path)
    procs.append(proc)
    port = proc.url().rsplit(":", 1)[1]
    token = proc.line("token: ").split()[1]
    assert len(token) >= 24
    with httpx2.Client(base_url=f"http://127.0.0.1:{port}") as c:
        assert c.get("/api/status").status_code == 401
        assert c.get("/openapi.json").status_code == 401
        assert c.post("/api/stop").status_code == 401
        auth = {"Authorization": f"Bearer {token}"}
        assert c.get("/api/status", headers=auth).json()["state"] in ("idle", "starting")
        rid = c.post("/api/requests", json={"item": 1}, headers=auth).json()["id"]
        _until(lambda: c.get(f"/api/requests/{rid}", headers=auth).json()["state"] == "success")
        assert c.post("/api/stop", headers=auth).status_code == 202
    assert proc.wait() == 0
    assert read_log(tmp_path / "s.jsonl")[-1]["outcome"] == "stopped"


def test_token_from_the_config_file(tmp_path: Path, procs: list[Proc]) -> None:
    secret = tmp_path / "console.token"
    secret.write_text("a-long-enough-token-from-a-file\n")
    secret.chmod(0o600)
    config = tmp_path / "mock.yaml"
    config.write_text(MOCK.read_text() + "\nserve:\n  token_file: console.token\n")
    proc = Proc(str(MISSIONS / "quick.yaml"), "--config", str(config), "--bind", "0.0.0.0:0", "--log", "t.jsonl",
                cwd=tmp_path)
    procs.append(proc)
    port = proc.url().rsplit(":", 1)[1]
    assert proc.line("token: ") == f"token: {secret} (every call needs 'Authorization: Bearer TOKEN')"
    with httpx2.Client(base_url=f"http://127.0.0.1:{port}") as c:
        auth = {"Authorization": "Bearer a-long-enough-token-from-a-file"}
        assert c.get("/api/status", headers=auth).status_code == 200
        assert c.post("/api/stop", headers=auth).status_code == 202
    assert proc.wait() == 0
    secret.chmod(0o644)
    bad = subprocess.run([str(EXE), "serve", str(MISSIONS / "quick.yaml"), "--config", str(config), "--bind",
                          "0.0.0.0:0"], cwd=tmp_path, capture_output=True, text=True, timeout=LIMIT, check=False)
    assert bad.returncode == 2
    assert bad.stderr.startswith(f"{config}:") and bad.stderr.count("\n") == 1
    assert bad.stderr.endswith(f": serve.token_file: {secret}: readable by others (mode 644); chmod 600 it\n")


@pytest.mark.parametrize("bind", ["nonsense", "127.0.0.1:99999", ":80"])
def test_bad_bind_is_one_line(tmp_path: Path, bind: str) -> None:
    r = subprocess.run([str(EXE), "serve", str(MISSIONS / "quick.yaml"), "--config", str(MOCK), "--bind", bind],
                       cwd=tmp_path, capture_output=True, text=True, timeout=LIMIT, check=False)
    assert r.returncode == 2
    assert r.stderr == (f"--bind: expected HOST:PORT with a port in 0..65535, e.g. 127.0.0.1:8765, got {bind!r}\n")
    assert not (tmp_path / "mmexec-logs").exists()


def test_port_in_use_is_one_line(tmp_path: Path) -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen(1)
        port = taken.getsockname()[1]
        r = subprocess.run([str(EXE), "serve", str(MISSIONS / "quick.yaml"), "--config", str(MOCK), "--bind",
                            f"127.0.0.1:{port}"], cwd=tmp_path, capture_output=True, text=True, timeout=LIMIT,
                           check=False)
    assert r.returncode == 2
    assert r.stderr == f"--bind: cannot listen on 127.0.0.1:{port}: Address already in use\n"


def test_serve_help_and_env() -> None:
    r = subprocess.run([str(EXE), "serve", "--help"], capture_output=True, text=True, timeout=LIMIT, check=False,
                       env={**os.environ, "COLUMNS": "200"})
    assert r.returncode == 0 and "--bind HOST:PORT" in r.stdout
