"""``mmexec serve``: the executive as a service (HTTP + WebSocket API, operator prompts).

* :mod:`.service`: the request queue shared with the tick loop, the streams, the runner;
* :mod:`.app`: the HTTP + WebSocket API (FastAPI);
* :mod:`.prompts`: operator channels for ``ask_operator`` (service, terminal, script);
* :mod:`.settings`: the config's ``serve:`` section and the API token;
* :mod:`.server`: ``mmexec serve`` itself: the tick loop in the main thread, uvicorn in
  another.
"""
