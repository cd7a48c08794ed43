"""The HTTP + WebSocket API of ``mmexec serve`` (FastAPI), over a :class:`Service`.

Every error is JSON ``{"error": "one line"}`` with a 4xx status: 401 no or wrong token,
404 unknown request / prompt / path, 409 not possible now (already ended, stopping),
413 body over ``serve.max_body``, 422 bad input (the same message ``--request`` prints),
429 queue full. Off loopback every call, the WebSocket included, needs the token:
``Authorization: Bearer TOKEN`` (or ``?token=TOKEN`` for a WebSocket, which browsers
cannot give headers). CORS is closed unless ``serve.cors_origins`` names origins. The
only files served are the browser console's (``/console/``, from the package's
``static/`` folder, no token needed: they hold no data). Shapes: docs/console.md.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import secrets
from collections.abc import Awaitable, Callable, MutableMapping
from typing import Any, Literal

from fastapi import Body, FastAPI, Query, Request, WebSocket, WebSocketDisconnect
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse, RedirectResponse, Response
from pydantic import BaseModel, Field
from starlette.exceptions import HTTPException as StarletteHTTPException

from mmexec.executive.serve.console import CONSOLE_CSP, static_assets
from mmexec.executive.serve.prompts import PromptAnsweredError, PromptClosedError
from mmexec.executive.serve.service import RECENT_EVENTS, TOPICS, Service, ServiceError
from mmexec.skills.operator import AnswerError

__all__ = ["create_app"]

log = logging.getLogger(__name__)

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
ASGIApp = Callable[[Scope, Receive, Send], Awaitable[None]]
#: where the browser console is served
CONSOLE_PREFIX = "/console"


class AnswerBody(BaseModel):
    """An operator's answer: true/false (confirm), the option (choose), [u, v] pixels (point)."""

    answer: bool | str | list[float] = Field(description="true/false, an option, or [u, v] pixels")
    source: Literal["api", "console"] = Field("api", description="who answers (the console says 'console')")


def _error(status: int, message: str) -> JSONResponse:
    return JSONResponse({"error": message}, status_code=status)


async def _send_error(send: Send, status: int, message: str) -> None:
    body = json.dumps({"error": message}).encode()
    await send({"type": "http.response.start", "status": status,
                "headers": [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode())]})
    await send({"type": "http.response.body", "body": body})


class Guard:
    """ASGI middleware in front of everything: the token check (when required) and the
    body cap (the whole body is read, at most ``max_body`` bytes, before the app sees it)."""

    def __init__(self, app: ASGIApp, *, token: str | None, max_body: int) -> None:
        self.app = app
        self.token = token
        self.max_body = max_body

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        kind = scope["type"]
        if kind not in ("http", "websocket"):
            await self.app(scope, receive, send)
            return
        if (self.token is not None and not self._authorised(scope) and not self._preflight(scope)
                and not self._console_file(scope)):
            if kind == "websocket":
                await send({"type": "websocket.close", "code": 4401, "reason": "token required"})
                return
            await _send_error(send, 401, f"{scope['method']} {scope['path']}: a valid token is required "
                                         "(Authorization: Bearer TOKEN)")
            return
        if kind == "http":
            headers = dict(scope.get("headers") or [])
            declared = headers.get(b"content-length")
            if declared is not None and not declared.isdigit():
                await _send_error(send, 400, f"{scope['method']} {scope['path']}: Content-Length is not a number")
                return
            if declared is not None and int(declared) > self.max_body:
                await _send_error(send, 413, f"{scope['method']} {scope['path']}: body over {self.max_body} bytes")
                return
            chunks: list[bytes] = []
            size = 0
            more = True
            while more:
                message = await receive()
                if message["type"] != "http.request":
                    return  # the client went away
                chunk = message.get("body", b"")
                size += len(chunk)
                if size > self.max_body:
                    await _send_error(send, 413, f"{scope['method']} {scope['path']}: body over {self.max_body} bytes")
                    return
                chunks.append(chunk)
                more = message.get("more_body", False)
            body = b"".join(chunks)
            sent = False

            async def replay() -> Message:
                nonlocal sent
                if not sent:
                    sent = True
                    return {"type": "http.request", "body": body, "more_body": False}
                return await receive()

            await self.app(scope, replay, send)
            return
        await self.app(scope, receive, send)

    @staticmethod
    def _preflight(scope: Scope) -> bool:
        """A browser's CORS preflight (it carries no token by design): the CORS layer
        answers it (only for the configured origins); no endpoint runs."""
        if scope["type"] != "http" or scope["method"] != "OPTIONS":
            return False
        names = {name for name, _ in scope.get("headers") or []}
        return b"origin" in names and b"access-control-request-method" in names

    @staticmethod
    def _console_file(scope: Scope) -> bool:
        """The console's static files need no token (a browser cannot send one with a page
        load; they hold no data): the page asks for the token and sends it with each call."""
        path = scope.get("path", "")
        return (scope["type"] == "http" and scope["method"] in ("GET", "HEAD")
                and (path == CONSOLE_PREFIX or path.startswith(CONSOLE_PREFIX + "/")))

    def _authorised(self, scope: Scope) -> bool:
        assert self.token is not None
        given = ""
        for name, value in scope.get("headers") or []:
            if name == b"authorization":
                scheme, _, rest = value.decode("latin-1").partition(" ")
                if scheme.lower() == "bearer":
                    given = rest.strip()
        if not given and scope["type"] == "websocket":
            from urllib.parse import parse_qs

            given = (parse_qs(scope.get("query_string", b"").decode("latin-1")).get("token") or [""])[0]
        return bool(given) and secrets.compare_digest(given.encode(), self.token.encode())


def create_app(service: Service, *, token: str | None = None) -> Any:
    """The ASGI app serving ``service``; ``token`` None: no token is asked for (loopback)."""
    settings = service.settings
    app = FastAPI(title="mmexec service", version="1",
                  description="Serve requests with a mission, watch the executive live, answer operator "
                              "prompts. See docs/console.md.")

    @app.exception_handler(ServiceError)
    async def _service_error(request: Request, exc: ServiceError) -> JSONResponse:
        return _error(exc.status, exc.message)

    @app.exception_handler(RequestValidationError)
    async def _validation_error(request: Request, exc: RequestValidationError) -> JSONResponse:
        first = exc.errors()[0] if exc.errors() else {}
        where = ".".join(str(p) for p in first.get("loc", ()))
        return _error(422, f"{request.method} {request.url.path}: {where}: {first.get('msg', 'invalid input')}")

    @app.exception_handler(StarletteHTTPException)
    async def _http_error(request: Request, exc: StarletteHTTPException) -> JSONResponse:
        return _error(exc.status_code, f"{request.method} {request.url.path}: {exc.detail}")

    @app.get("/", summary="What this server offers")
    def index() -> dict[str, Any]:
        return {"service": "mmexec", "api": "/api/status", "stream": "/api/stream", "openapi": "/openapi.json",
                "docs": "/docs", "console": CONSOLE_PREFIX + "/"}

    assets = static_assets()

    @app.api_route(CONSOLE_PREFIX, methods=["GET", "HEAD"], include_in_schema=False)
    def console_root() -> Response:
        return RedirectResponse(CONSOLE_PREFIX + "/", status_code=307)

    @app.api_route(CONSOLE_PREFIX + "/{name:path}", methods=["GET", "HEAD"], include_in_schema=False)
    def console_file(name: str) -> Response:
        """The browser console: only the files of the package's static folder, listed when
        the app was made (no path from the URL reaches the file system)."""
        asset = assets.get(name or "index.html")
        if asset is None:
            raise ServiceError(404, f"GET {CONSOLE_PREFIX}/{name}: no such console file")
        headers = {"Cache-Control": "no-cache", "X-Content-Type-Options": "nosniff"}
        if asset.content_type == "text/html":
            headers["Content-Security-Policy"] = CONSOLE_CSP
        return Response(asset.path.read_bytes(), media_type=asset.content_type, headers=headers)

    @app.get("/api/mission", summary="The mission: its request fields (the request form) and its nodes")
    def mission() -> dict[str, Any]:
        return service.describe()

    @app.get("/api/events", summary="The last event-log records (oldest first)")
    def events(limit: int = Query(200, ge=0, le=RECENT_EVENTS, description="how many")) -> list[dict[str, Any]]:
        return service.events(limit)

    @app.get("/api/status", summary="The executive's state, the running request, queue length, counts")
    def status() -> dict[str, Any]:
        return service.status()

    @app.get("/api/requests", summary="The running request, the queue and recently finished requests")
    def list_requests() -> dict[str, Any]:
        return service.requests()

    @app.post("/api/requests", status_code=202, summary="Queue a request (checked like --request)")
    def submit(fields: dict[str, Any] = Body(..., examples=[{"item": 3}],  # noqa: B008
                                             description="the request's fields, as the mission declares them "
                                                         "(one with a default may be left out)")
               ) -> dict[str, Any]:
        return service.submit(fields).to_json()

    @app.get("/api/requests/{rid}", summary="One request")
    def get_request(rid: int) -> dict[str, Any]:
        return service.get(rid).to_json()

    @app.delete("/api/requests/{rid}", summary="Cancel a queued request, or halt it while it runs")
    def cancel(rid: int) -> JSONResponse:
        req = service.cancel(rid)
        return JSONResponse(req.to_json(), status_code=200 if req.state == "dropped" else 202)

    @app.post("/api/halt", status_code=202, summary="Halt the running request (the queue goes on)")
    def halt() -> dict[str, Any]:
        return service.halt().to_json()

    @app.post("/api/pause", summary="Start no new request until resumed (the running one goes on)")
    def pause() -> dict[str, Any]:
        return service.set_paused(True)

    @app.post("/api/resume", summary="Serve the queue again")
    def resume() -> dict[str, Any]:
        return service.set_paused(False)

    @app.post("/api/stop", status_code=202, summary="Stop: halt the tree, drop the queue, stop the robot, exit")
    def stop() -> dict[str, Any]:
        return service.stop()

    @app.get("/api/prompts", summary="Operator prompts waiting for an answer")
    def prompts() -> list[dict[str, Any]]:
        return service.open_prompts()

    @app.get("/api/prompts/{pid}/image", summary="A prompt's image (JPEG)",
             responses={200: {"content": {"image/jpeg": {}}}})
    def prompt_image(pid: str) -> Response:
        prompt = service.prompts.get(pid)
        if prompt is None or prompt.image is None:
            raise ServiceError(404, f"prompt {pid!r}: no such open prompt with an image")
        return Response(prompt.image, media_type="image/jpeg")

    @app.post("/api/prompts/{pid}/answer", summary="Answer an operator prompt")
    def answer(pid: str, body: AnswerBody) -> dict[str, Any]:
        where = f"POST /api/prompts/{pid}/answer"
        try:
            value = service.prompts.answer(pid, body.answer, body.source)
        except PromptAnsweredError as e:
            raise ServiceError(409, f"{where}: {e}") from None
        except PromptClosedError as e:
            raise ServiceError(404, f"{where}: {e}") from None
        except AnswerError as e:
            raise ServiceError(422, f"{where}: {e}") from None
        return {"id": pid, "answer": value, "source": body.source}

    @app.websocket("/api/stream")
    async def stream(ws: WebSocket, topics: str | None = Query(None, description="comma-separated; default all")
                     ) -> None:
        wanted = TOPICS if not topics else tuple(t.strip() for t in topics.split(",") if t.strip())
        unknown = [t for t in wanted if t not in TOPICS]
        await ws.accept()
        if unknown:
            await ws.send_json({"type": "error", "data": {
                "error": f"/api/stream: unknown topic {unknown[0]!r} (topics: {', '.join(TOPICS)})"}})
            await ws.close(code=1008)
            return
        client = service.hub.attach(asyncio.get_running_loop(), wanted)
        await ws.send_json({"type": "hello", "data": {"topics": list(wanted), "status": service.status(),
                                                      "prompts": service.open_prompts()}})

        async def pump() -> None:
            while True:
                await ws.send_text(await client.queue.get())

        async def drain() -> None:
            with contextlib.suppress(WebSocketDisconnect):  # the normal end of a stream
                while True:
                    await ws.receive_text()  # clients have nothing to say; answers go over HTTP

        tasks = [asyncio.ensure_future(pump()), asyncio.ensure_future(drain())]
        try:
            done, _ = await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
            for t in done:
                if t.exception() is not None:  # the client went away while a message was sent
                    log.debug("stream client ended: %r", t.exception())
        finally:
            for t in tasks:
                t.cancel()
            service.hub.detach(client)

    if settings.cors_origins:
        from fastapi.middleware.cors import CORSMiddleware

        app.add_middleware(CORSMiddleware, allow_origins=list(settings.cors_origins),
                           allow_methods=["GET", "POST", "DELETE"], allow_headers=["Authorization", "Content-Type"])
    return Guard(app, token=token, max_body=settings.max_body)
