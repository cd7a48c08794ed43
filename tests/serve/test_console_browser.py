"""The operator console in a real browser: Debian's headless Chromium driven by
Playwright, against ``mmexec serve`` running in this process on the sim backend.

One scenario, as an operator would use it (a screenshot of each step is saved under the
test's output folder, named in its output; ``MMEXEC_CONSOLE_SHOTS=DIR`` saves them there
instead):

1. ``trees/fetch_item.yaml`` on ``config/locobot_sim.yaml``: open the console, submit two
   fetch requests from the form, watch the tree and the robot's pose change live, cancel
   the second from the queue, submit a third, press STOP while the arm moves: the tree
   halts, the simulated base and arm are still (ground truth) within 0.2 s of sim time of
   the press, the event log has the halt, the page shows it;
2. reload the page: the same picture comes back; shut the service down from the page
   and start it again on the same port (``tests/serve/missions/ask_point.yaml``, the
   same simulated robot): the page reconnects by itself;
3. answer an operator prompt by clicking on its camera image: the answer is the pixel
   clicked; a bad request shows its located error at the field.

The sim runs faster than real time, so the test holds the tick loop (a tick hook, as a
slow tick would) once the arm moves during ``pick``, until the page's STOP has reached the
service: "while the arm moves" is then certain, not a race with the browser. Nothing
else waits on wall time: every wait polls for a state with a generous deadline.

Without a browser (no ``chromium``, or Playwright not installed) the test is skipped
with the install command to run (``make browser``), except under ``CI=true``, where it
fails.
"""

from __future__ import annotations

import io
import math
import os
import re
import shutil
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from mmexec.executive.config import build_robot
from mmexec.executive.eventlog import read_log
from mmexec.executive.runner import RunOptions
from mmexec.executive.serve.app import create_app
from mmexec.executive.serve.server import BindAddress, ServerThread, open_socket, serve

ROOT = Path(__file__).resolve().parents[2]
SIM = ROOT / "config" / "locobot_sim.yaml"
FETCH = ROOT / "trees" / "fetch_item.yaml"
ASK_POINT = Path(__file__).resolve().parent / "missions" / "ask_point.yaml"
PICK = "fetch_item/pick_item/sequence/pick"
#: [wall s] how long any one step may take before the test fails (not a timing assert)
PATIENCE = 60.0
#: [sim s] the base and arm must be still this soon after STOP
STOP_BOUND = 0.2
#: [rad/s] an arm joint slower than this is still (0.6 deg/s: the sim arm's position
#: hold settles the last few mrad after its 0.15 s braking ramp)
STILL_JOINT_SPEED = 0.01
#: Chromium flags that work on a closed network, as root, without a display
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync"]


def _chromium() -> str:
    """The browser to drive, or skip (fail under CI=true) saying how to install it."""
    path = os.environ.get("MMEXEC_CHROMIUM") or shutil.which("chromium") or ""
    problem = ""
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        problem = "Playwright is not installed: `make install` (pip install -e '.[dev]')"
    if not problem and not path:
        problem = "Debian's chromium is not installed: `make browser` (as root: apt-get install chromium chromium-driver)"
    if problem:
        message = f"browser test: {problem}"
        if os.environ.get("CI") == "true":
            pytest.fail(message + " (CI=true: the browser must be installable here)")
        pytest.skip(message)
    return path


class _Lines(io.TextIOBase):
    """The service's console output, kept (the first line names the URL)."""

    def __init__(self) -> None:
        self.lines: deque[str] = deque(maxlen=500)

    def write(self, text: str) -> int:
        self.lines.extend(text.splitlines())
        return len(text)

    def isatty(self) -> bool:
        return False


def _wait(predicate: Callable[[], Any], what: str) -> Any:
    deadline = time.monotonic() + PATIENCE
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"{what}: not within {PATIENCE} s")
        time.sleep(0.01)


class Served:
    """``mmexec serve`` in a thread of this process (the tick loop and uvicorn, exactly as
    the command runs them), so the test can see the simulated robot's ground truth."""

    def __init__(self, mission: Path, log_path: Path, bind: str,
                 setup: Callable[[Any], None] | None = None) -> None:
        self.out = _Lines()
        self.runner: Any = None
        self.code: int | None = None
        self.error: BaseException | None = None
        self.log_path = log_path
        self._setup = setup
        options = RunOptions(mission=mission, config=SIM, log_path=log_path, seed=1)
        self.thread = threading.Thread(target=self._run, args=(options, bind), name="served", daemon=True)
        self.thread.start()
        line = _wait(lambda: self.error or next((x for x in self.out.lines if x.startswith("mmexec serve:")), None),
                     "the service's first line")
        if self.error is not None:
            raise self.error
        self.url = re.search(r"(http://[^/]+)/api/status", line).group(1)  # type: ignore[union-attr]
        _wait(lambda: self.runner.service.status()["state"] != "starting", "the service up")

    def _made(self, runner: Any) -> None:
        self.runner = runner
        if self._setup is not None:
            self._setup(runner)

    def _run(self, options: RunOptions, bind: str) -> None:
        try:
            self.code = serve(options, bind, out=self.out, err=self.out, made=self._made)
        except BaseException as e:  # noqa: BLE001 - re-raised in the test thread
            self.error = e

    def join(self) -> int | None:
        self.thread.join(PATIENCE)
        assert not self.thread.is_alive(), "the service did not stop"
        if self.error is not None:
            raise self.error
        return self.code

    def records(self, event: str) -> list[dict[str, Any]]:
        return [r for r in read_log(self.log_path) if r["event"] == event]


class ArmGate:
    """The first service's simulated robot, watched: after every step of the simulation
    (between two ticks) it samples the ground truth (base pose, arm joint positions and
    velocities), reads the lidar now and then as a localisation skill would (the map shows
    the scan), and once the arm moves during ``pick`` it holds the tick loop there until
    the STOP pressed in the page has reached the service (the running request is
    ``halting``). ``pressed_at`` is the sim time of the press; the executive takes the
    STOP at the next tick, which starts at that same sim time."""

    def __init__(self) -> None:
        self.runner: Any = None
        self.robot: Any = None
        self.samples: list[tuple[float, float, float, float, np.ndarray, np.ndarray]] = []
        self.holding = threading.Event()
        self.abort = threading.Event()  # the test failed: let the tick loop go
        self.pressed_at: float | None = None
        self.moving_at_press = 0.0

    def attach(self, runner: Any) -> None:
        self.runner = runner
        runner.robot_factory = self.build
        runner.add_log_listener(self.on_record)

    def build(self, loaded: Any) -> Any:
        robot = self.robot = build_robot(loaded, seed=runner_seed(self.runner))
        step = robot.spin

        def spin(period: float) -> None:
            step(period)
            self.stepped(robot)

        robot.spin = spin
        return robot

    def sample(self, robot: Any) -> None:
        pose = robot.truth.base_pose()
        st = robot.arm.state()
        self.samples.append((robot.clock.now(), pose.x, pose.y, pose.theta, np.array(st.positions),
                             np.array(st.velocities)))

    def on_record(self, record: dict[str, Any]) -> None:
        if record.get("event") == "request_end" and self.robot is not None:
            self.sample(self.robot)  # the state the request left the robot in
            if self.pressed_at is not None:  # let physics go on 0.4 s (idle, the sim holds still)
                for _ in range(8):
                    self.robot.spin(0.05)

    def stepped(self, robot: Any) -> None:
        self.sample(robot)
        if len(self.samples) % 4 == 0:
            robot.lidar.scan()
        if self.pressed_at is not None or self.holding.is_set():
            return
        speed = float(np.max(np.abs(self.samples[-1][5])))
        if self.runner.streams.tree.status.get(PICK) != "RUNNING" or speed < 0.05:
            return
        self.holding.set()  # the arm moves: wait for the page's STOP
        service = self.runner.service
        _wait(lambda: self.abort.is_set() or (service.requests()["current"] or {}).get("reason") == "halting",
              "STOP from the page")
        self.pressed_at = robot.clock.now()
        self.moving_at_press = speed

    def still_from(self) -> float:
        """The first sim time from which, in every later sample, each arm joint turns
        slower than :data:`STILL_JOINT_SPEED` and the base has not moved since the sample
        before (0.1 mm, 0.1 mrad)."""
        still = math.inf
        for i in range(len(self.samples) - 1, -1, -1):
            t, x, y, th, _q, dq = self.samples[i]
            if float(np.max(np.abs(dq))) >= STILL_JOINT_SPEED:
                break
            still = t
            if i > 0:
                _, px, py, pth, _, _ = self.samples[i - 1]
                if math.hypot(x - px, y - py) > 1e-4 or abs(th - pth) > 1e-4:
                    break
        return still


def runner_seed(runner: Any) -> int | None:
    return runner.options.seed  # type: ignore[no-any-return]


@pytest.fixture
def shots(tmp_path: Path) -> Iterator[Callable[[Any, str], Path]]:
    folder = Path(os.environ.get("MMEXEC_CONSOLE_SHOTS") or tmp_path / "console-screenshots")
    folder.mkdir(parents=True, exist_ok=True)
    taken: list[Path] = []

    def shoot(page: Any, name: str) -> Path:
        path = folder / f"{len(taken) + 1:02d}-{name}.png"
        page.screenshot(path=str(path), full_page=True)
        taken.append(path)
        return path

    yield shoot
    print(f"console screenshots: {folder} ({len(taken)})")


def _report_failure(page: Any, shots: Callable[[Any, str], Path], servers: list[Served | None]) -> None:
    """What a failure needs to be understood: the page as it was, each service's output
    and its log's last records."""
    try:
        print(f"screenshot of the failure: {shots(page, 'failure')}")
    except Exception as e:  # noqa: BLE001 - the report must not hide the failure
        print(f"no screenshot of the failure: {e}")
    for served in servers:
        if served is None:
            continue
        print(f"--- {served.log_path.name}: output", *served.out.lines, sep="\n")
        records = read_log(served.log_path) if served.log_path.exists() else []
        print(f"--- {served.log_path.name}: last records", *(str(r)[:300] for r in records[-15:]), sep="\n")


def _pose_x(page: Any) -> float:
    """The x [m] of the pose the map's readout shows (-inf before one)."""
    m = re.search(r"x (\S+) m", str(page.inner_text("#pose")))
    return float(m.group(1)) if m else -math.inf


def test_console_in_chromium(tmp_path: Path, shots: Callable[[Any, str], Path]) -> None:
    chromium = _chromium()
    from playwright.sync_api import expect, sync_playwright

    gate = ArmGate()
    first = Served(FETCH, tmp_path / "fetch.jsonl", "127.0.0.1:0", setup=gate.attach)
    second: Served | None = None
    try:
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=chromium, args=CHROMIUM_ARGS)
            page = browser.new_page(viewport={"width": 1480, "height": 1000})
            errors: list[str] = []
            page.on("pageerror", lambda e: errors.append(str(e)))
            expect.set_options(timeout=PATIENCE * 1000)
            try:
                # ---------------------------------------------------------------- 1. open, submit two
                page.goto(first.url + "/console/")
                expect(page.locator("#conn")).to_have_text("live")
                expect(page.locator("#mission-name")).to_have_text("fetch_item")
                expect(page.locator("#field-item")).to_be_visible()
                expect(page.locator("#pose")).to_contain_text("x 1.50 m  y 2.00 m")  # home, before anything moves
                page.evaluate("""() => {  // every pose and tree change the page shows, as it shows them
                    window.seen = {poses: new Set(), nodes: new Set()};
                    new MutationObserver(() => window.seen.poses.add(document.getElementById('pose').textContent))
                        .observe(document.getElementById('pose'), {childList: true, characterData: true, subtree: true});
                    new MutationObserver((records) => records.forEach((r) =>
                            window.seen.nodes.add(r.target.dataset.path + ' ' + r.target.dataset.status)))
                        .observe(document.getElementById('tree'), {attributes: true, subtree: true,
                                                                   attributeFilter: ['data-status']});
                }""")
                shots(page, "open")
                for item in ("3", "5"):
                    page.fill("#field-item", item)
                    page.click("#submit")
                expect(page.locator('#queue li[data-request="2"]')).to_have_attribute("data-state", "queued")

                # ---------------------------------------------------------------- live tree and pose
                _wait(gate.holding.is_set, "the arm moving during pick")
                expect(page.locator(f'li[data-path="{PICK}"]')).to_have_attribute("data-status", "RUNNING")
                expect(page.locator('li[data-path="fetch_item/pick_item/sequence/find"]')).to_have_attribute(
                    "data-status", "SUCCESS")
                _wait(lambda: _pose_x(page) > 3.5, "the pose at the shelf")
                seen = page.evaluate("() => ({poses: window.seen.poses.size, nodes: window.seen.nodes.size})")
                assert seen["poses"] >= 3 and seen["nodes"] >= 10, seen  # it changed on the page, not after a reload
                page.click(f'li[data-path="{PICK}"] > .row')
                expect(page.locator("#node-info")).to_contain_text("pick(marker={request.item})")
                expect(page.locator("#node-info")).to_contain_text(re.compile(r"request\.item\s*3"))  # the blackboard
                expect(page.locator("#camera-info")).to_contain_text("detection")
                page.click("#bb-all summary")
                expect(page.locator("#bb-table")).to_contain_text("pick_item.attempts")
                shots(page, "live-tree-and-pose")

                # ---------------------------------------------------------------- cancel 2, submit 3
                page.click('#queue li[data-request="2"] button.cancel')
                expect(page.locator('#finished li[data-request="2"]')).to_have_attribute("data-state", "dropped")
                page.fill("#field-item", "6")
                page.click("#submit")
                expect(page.locator('#queue li[data-request="3"]')).to_have_attribute("data-state", "queued")
                shots(page, "cancelled-and-resubmitted")

                # ---------------------------------------------------------------- STOP while the arm moves
                page.click("#stop")
                expect(page.locator('#finished li[data-request="1"]')).to_have_attribute("data-state", "cancelled")
                expect(page.locator("#state")).to_have_text("paused")
                expect(page.locator(f'li[data-path="{PICK}"]')).to_have_class(re.compile(r"\bhalted\b"))
                halt_row = page.locator("#log .entry.fail").filter(has=page.get_by_text("halt", exact=True))
                expect(halt_row).to_contain_text("halted through the API")  # the log's failure, highlighted
                shots(page, "stopped")
                assert gate.pressed_at is not None and gate.moving_at_press > 0.05
                halt = first.records("halt")
                assert [h["detail"] for h in halt] == ["halted through the API"] and halt[0]["reason"] == "cancel"
                assert halt[0]["t"] == gate.pressed_at  # taken at the next tick, which starts then
                still = gate.still_from()
                assert still - gate.pressed_at <= STOP_BOUND + 1e-6, (
                    f"base and arm still {still - gate.pressed_at:.3f} s of sim time after STOP")
                assert float(np.max(np.abs(gate.samples[-1][5]))) < 1e-3  # and at rest 0.4 s after the request's end
                end = first.records("request_end")[0]
                assert (end["id"], end["outcome"], end["reason"]) == (1, "cancelled", "halted through the API")
                dropped = first.records("request_dropped")[0]
                assert (dropped["id"], dropped["reason"]) == (2, "cancelled through the API")
                assert first.records("paused")

                # ---------------------------------------------------------------- 2. reload; restart
                page.reload()
                expect(page.locator("#conn")).to_have_text("live")
                expect(page.locator('#finished li[data-request="1"]')).to_have_attribute("data-state", "cancelled")
                expect(page.locator('#finished li[data-request="2"]')).to_have_attribute("data-state", "dropped")
                expect(page.locator('#queue li[data-request="3"]')).to_have_attribute("data-state", "queued")
                expect(page.locator("#state")).to_have_text("paused")
                expect(page.locator(f'li[data-path="{PICK}"]')).to_have_attribute("data-status", "INVALID")
                expect(page.locator(f'li[data-path="{PICK}"]')).to_have_class(re.compile(r"\bhalted\b"))  # from the log
                expect(page.locator("#log .entry", has_text="request_dropped")).to_be_visible()
                shots(page, "reloaded")
                port = first.url.rsplit(":", 1)[1]
                page.click("#shutdown")
                page.click("#shutdown")  # confirm
                assert first.join() == 0
                expect(page.locator("#conn")).to_have_text("offline")
                shots(page, "service-down")
                assert first.records("request_dropped")[-1]["id"] == 3

                second = Served(ASK_POINT, tmp_path / "ask.jsonl", f"127.0.0.1:{port}")
                expect(page.locator("#conn")).to_have_text("live")
                expect(page.locator("#mission-name")).to_have_text("ask_point")
                expect(page.locator("#state")).to_have_text("idle")
                expect(page.locator("#finished li[data-request]")).to_have_count(0)
                # the request form is rebuilt for the new mission in the same step that shows
                # its description (the name comes earlier): a value typed before that is lost
                expect(page.locator("#mission-doc")).to_have_text("Click the item.")

                # ---------------------------------------------------------------- 3. click prompt
                page.fill("#field-item", "3")
                expect(page.locator("#field-item")).to_have_value("3")
                page.click("#submit")
                image = page.locator(".prompt.kind-point canvas")
                expect(image).to_be_visible()
                prompt = _wait(lambda: second.runner.service.open_prompts(), "the prompt")[0]
                w, h = prompt["image_size"]
                _wait(lambda: image.evaluate("c => c.width") == w, "the prompt's image loaded")
                shots(page, "prompt")
                box = image.bounding_box()
                assert box is not None
                x, y = round(box["width"] * 0.3), round(box["height"] * 0.6)
                image.click(position={"x": x, "y": y})
                expect(page.locator("#finished li[data-request='1']")).to_have_attribute("data-state", "success")
                answer = second.records("operator_answer")[0]
                assert answer["source"] == "console"
                u, v = answer["answer"]  # the pixel clicked (the image is shown scaled: within a pixel)
                assert abs(u - x * w / box["width"]) <= 1 and abs(v - y * h / box["height"]) <= 1, (u, v)
                expect(page.locator("#prompt-card")).to_be_hidden()
                page.click('li[data-path="ask_point/click"] > .row')  # its output on the blackboard
                expect(page.locator("#node-info")).to_contain_text(re.compile(rf"pixel\s*\[{u:g},{v:g}\]"))
                shots(page, "prompt-answered")

                # ---------------------------------------------------------------- bad request
                page.fill("#field-item", "seven")
                page.click("#submit")
                expect(page.locator("#request-error")).to_have_text(
                    "POST /api/requests: request field 'item': expected int, got 'seven'")
                expect(page.locator("#field-item")).to_have_class(re.compile(r"\binvalid\b"))
                shots(page, "bad-request")
                assert errors == []
                browser.close()
            except BaseException:
                _report_failure(page, shots, [first, second])
                raise
    finally:
        gate.abort.set()
        for served in (first, second):
            if served is not None and served.thread.is_alive():
                served.runner.service.stop()
                served.thread.join(PATIENCE)
    assert second is not None and second.join() == 0


def test_console_asks_for_the_token_in_chromium(live: Any, shots: Callable[[Any, str], Path]) -> None:
    """Off loopback every call needs the token: the page loads without it, asks for it
    when the service refuses, and takes it from the URL's fragment (never sent)."""
    chromium = _chromium()
    from playwright.sync_api import expect, sync_playwright

    token = "t0ken-" + "x" * 20
    svc = live()  # the mock service; its app again, guarded, on a real loopback socket
    sock = open_socket(BindAddress("127.0.0.1", 0))
    server = ServerThread(create_app(svc.service, token=token), sock)
    server.start()
    url = f"http://127.0.0.1:{sock.getsockname()[1]}/console/"
    try:
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=chromium, args=CHROMIUM_ARGS)
            page = browser.new_page(viewport={"width": 1280, "height": 800})
            expect.set_options(timeout=PATIENCE * 1000)
            page.goto(url)
            expect(page.locator("#token-form")).to_be_visible()
            expect(page.locator("#conn")).to_have_text("offline")
            page.fill("#token-input", "wrong-" + "y" * 20)
            page.click("#token-form button")
            expect(page.locator("#token-why")).to_have_text("The service refused this token; enter its token")
            expect(page.locator("#banner")).to_be_hidden()  # not "cannot be reached": it can, without the token
            shots(page, "token-asked")
            page.fill("#token-input", token)
            page.click("#token-form button")
            expect(page.locator("#conn")).to_have_text("live")
            expect(page.locator("#mission-name")).to_have_text("quick")
            expect(page.locator("#token-form")).to_be_hidden()

            other = browser.new_page(viewport={"width": 1280, "height": 800})
            other.goto(url + "#token=" + token)
            expect(other.locator("#conn")).to_have_text("live")
            expect(other.locator("#field-item")).to_be_visible()
            assert "token" not in other.url  # taken out of the address bar (and history)
            other.fill("#field-item", "4")
            other.click("#submit")
            expect(other.locator('#finished li[data-request="1"]')).to_have_attribute("data-state", "success")
            browser.close()
    finally:
        server.stop()
        sock.close()
