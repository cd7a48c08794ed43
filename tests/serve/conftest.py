"""A live service for the API tests: a ServeRunner ticking in a thread (as the main
thread does under ``mmexec serve``), the FastAPI app behind FastAPI's TestClient."""

from __future__ import annotations

import io
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from mmexec.executive.eventlog import read_log
from mmexec.executive.runner import RunOptions
from mmexec.executive.serve.app import create_app
from mmexec.executive.serve.service import ServeRunner, Service

ROOT = Path(__file__).resolve().parents[2]
MISSIONS = Path(__file__).resolve().parent / "missions"
MOCK = ROOT / "config" / "mock.yaml"
#: [wall s] how long a test waits for the service to reach a state before failing
PATIENCE = 60.0


def mock_config(tmp_path: Path, serve_section: str) -> Path:
    """config/mock.yaml with a ``serve:`` section appended."""
    path = tmp_path / "mock_serve.yaml"
    path.write_text(MOCK.read_text() + "\n" + serve_section)
    return path


class Console(io.TextIOBase):
    """The run's console for tests: keeps the last lines only (a long run's output must
    not look like the service's memory growing)."""

    def __init__(self, keep: int = 500) -> None:
        self.lines: deque[str] = deque(maxlen=keep)

    def write(self, text: str) -> int:
        self.lines.extend(text.splitlines())
        return len(text)

    def isatty(self) -> bool:
        return False

    def getvalue(self) -> str:
        return "\n".join(self.lines)


class Live:
    """A started service; ``client`` talks to its API, :meth:`close` stops it."""

    def __init__(self, mission: Path, config: Path, log_path: Path, *, token: str | None = None,
                 params: dict[str, Any] | None = None) -> None:
        self.log_path = log_path
        self.service = Service()
        self.out = Console()
        self.runner = ServeRunner(RunOptions(mission=mission, config=config, log_path=log_path,
                                             params=dict(params or {})), self.service, out=self.out, err=self.out)
        self.runner.prepare()
        self.app = create_app(self.service, token=token)
        self.client = TestClient(self.app)
        self.code: int | None = None
        self.error: BaseException | None = None
        self.thread = threading.Thread(target=self._run, name="test-tick-loop", daemon=True)
        self.thread.start()
        self.wait(lambda: self.service.status()["state"] != "starting")

    def _run(self) -> None:
        try:
            self.code = self.runner.run()
        except BaseException as e:  # noqa: BLE001 - re-raised in the test thread by wait() and close()
            self.error = e

    def wait(self, predicate: Callable[[], Any], what: str = "the service") -> Any:
        """Poll ``predicate`` until it is truthy (no wall-time assertion: a deadline only
        turns a hang into a failure)."""
        deadline = time.monotonic() + PATIENCE
        while True:
            value = predicate()
            if value:
                return value
            if self.error is not None:
                raise AssertionError(f"the tick loop raised {self.error!r}")
            if time.monotonic() > deadline:
                raise AssertionError(f"{what} did not get there within {PATIENCE} s")
            time.sleep(0.005)

    def finished(self, rid: int) -> dict[str, Any]:
        """Wait until request ``rid`` ended; its JSON."""
        def done() -> dict[str, Any] | None:
            req = self.service.get(rid).to_json()
            return req if req["state"] not in ("queued", "running") else None
        return self.wait(done, f"request {rid}")  # type: ignore[no-any-return]

    def prompt(self) -> dict[str, Any]:
        """Wait for an open prompt; its JSON."""
        return self.wait(lambda: (self.client.get("/api/prompts").json() or [None])[0], "a prompt")  # type: ignore[no-any-return]

    def close(self) -> int | None:
        self.service.stop()
        self.thread.join(PATIENCE)
        self.client.close()
        if self.error is not None:
            raise self.error
        return self.code

    def records(self, event: str | None = None) -> list[dict[str, Any]]:
        recs = read_log(self.log_path)
        return [r for r in recs if event is None or r["event"] == event]


def _stream_until(ws: Any, until: Callable[[dict[str, Any]], bool], limit: int = 5000) -> list[dict[str, Any]]:
    out = []
    for _ in range(limit):
        msg = ws.receive_json()
        out.append(msg)
        if until(msg):
            return out
    raise AssertionError("the stream never sent the expected message")


@pytest.fixture
def stream_until() -> Callable[..., list[dict[str, Any]]]:
    """``stream_until(ws, pred)``: the /api/stream messages read until (and with) the first
    one ``pred`` accepts; fails after 5000 messages without it."""
    return _stream_until


@pytest.fixture
def missions() -> Path:
    """The folder of the service tests' missions."""
    return MISSIONS


@pytest.fixture
def serve_config(tmp_path: Path) -> Callable[[str], Path]:
    """``serve_config("serve:\n  max_body: 2048\n")``: config/mock.yaml with that section."""
    return lambda section: mock_config(tmp_path, section)


@pytest.fixture
def live(tmp_path: Path) -> Iterator[Callable[..., Live]]:
    """``live(mission_name, config=..., token=..., params=...)`` starts a service."""
    started: list[Live] = []

    def start(mission: str = "quick", *, config: Path = MOCK, token: str | None = None,
              params: dict[str, Any] | None = None) -> Live:
        svc = Live(MISSIONS / f"{mission}.yaml", config, tmp_path / f"events-{len(started)}.jsonl", token=token,
                   params=params)
        started.append(svc)
        return svc

    yield start
    for svc in started:
        if svc.thread.is_alive():
            svc.close()
