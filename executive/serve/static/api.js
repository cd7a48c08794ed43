// The service's HTTP API and live stream, as the console uses them (docs/console.md).
//
// The token (needed when the service listens beyond loopback) comes from the page's
// URL fragment (#token=...: a fragment is never sent to the server nor logged), is kept
// for this tab in sessionStorage, and goes with every call as a Bearer header and with
// the stream as ?token= (browsers cannot set headers on a WebSocket).

const TOKEN_KEY = "mmexec.token";

export function takeTokenFromUrl() {
  const m = /(?:^|[#&])token=([^&]+)/.exec(location.hash);
  if (m) {
    sessionStorage.setItem(TOKEN_KEY, decodeURIComponent(m[1]));
    history.replaceState(null, "", location.pathname + location.search);
  }
}

export function token() {
  return sessionStorage.getItem(TOKEN_KEY) || "";
}

export function setToken(value) {
  sessionStorage.setItem(TOKEN_KEY, value.trim());
}

// Listeners told when a call or the stream is refused for want of a token.
const unauthorised = new Set();
export function onUnauthorised(fn) {
  unauthorised.add(fn);
}
function refused() {
  for (const fn of unauthorised) fn();
}

// One API call: resolves to {ok, status, data} (data: the JSON body, or {error} for
// a network failure); never throws.
export async function api(method, path, body) {
  const headers = {};
  if (token()) headers.Authorization = `Bearer ${token()}`;
  if (body !== undefined) headers["Content-Type"] = "application/json";
  let res;
  try {
    res = await fetch(path, {method, headers, body: body === undefined ? undefined : JSON.stringify(body),
                             cache: "no-store"});
  } catch (e) {
    return {ok: false, status: 0, data: {error: `${method} ${path}: the service cannot be reached (${e.message})`}};
  }
  if (res.status === 401) refused();
  let data = null;
  try {
    data = await res.json();
  } catch (e) {
    data = {error: `${method} ${path}: ${res.status} ${res.statusText}`};
  }
  return {ok: res.ok, status: res.status, data};
}

// An image the API serves (a prompt's), as an object URL (the token goes as a header).
export async function imageUrl(path) {
  const headers = token() ? {Authorization: `Bearer ${token()}`} : {};
  const res = await fetch(path, {headers, cache: "no-store"});
  if (res.status === 401) refused();
  if (!res.ok) throw new Error(`GET ${path}: ${res.status}`);
  return URL.createObjectURL(await res.blob());
}

// The live stream: reconnects by itself (0.5 s, then up to 5 s apart) until stopped.
// onMessage({type, data}) for each message; onState("up" | "down", detail).
export class Stream {
  constructor(onMessage, onState) {
    this.onMessage = onMessage;
    this.onState = onState;
    this.delay = 500;
    this.ws = null;
    this.timer = null;
  }

  connect() {
    clearTimeout(this.timer);
    const scheme = location.protocol === "https:" ? "wss" : "ws";
    const query = token() ? `?token=${encodeURIComponent(token())}` : "";
    const ws = new WebSocket(`${scheme}://${location.host}/api/stream${query}`);
    this.ws = ws;
    let opened = false;
    ws.onopen = () => {
      opened = true;
      this.delay = 500;
      this.onState("up", "");
    };
    ws.onmessage = (ev) => {
      let msg;
      try {
        msg = JSON.parse(ev.data);
      } catch (e) {
        return;
      }
      this.onMessage(msg);
    };
    ws.onclose = (ev) => {
      if (this.ws !== ws) return;
      // A refused handshake reaches a browser as a plain failure (1006), not as 4401: ask
      // the API why (a 401 there brings up the token form).
      if (ev.code === 4401) refused();
      else if (!opened) api("GET", "/api/status");
      const wait = this.delay;
      this.delay = Math.min(5000, this.delay * 2);
      this.onState("down", `reconnecting in ${(wait / 1000).toFixed(1)} s`);
      this.timer = setTimeout(() => this.connect(), wait);
    };
  }

  // Reconnect now (a token was entered).
  restart() {
    const old = this.ws;
    this.ws = null;
    if (old) old.close();
    this.delay = 500;
    this.connect();
  }
}
