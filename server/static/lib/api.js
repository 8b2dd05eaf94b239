// The advisory service's API (docs/SERVICE.md), from the same origin: REST calls, and a trip's fix
// transport (WebSocket first, REST POST when the socket is not open, the socket retried in the background).

export class ApiError extends Error {
  constructor(status, body) {
    super(body?.message || `HTTP ${status}`);
    this.status = status;
    this.code = body?.error ?? "http_error";
  }
}

/** The service's root, relative to the page (the app lives at <root>/app/), so a proxy's prefix is kept. */
export const SERVICE_ROOT = new URL("../", document.baseURI);

export async function call(method, path, { body, token, signal } = {}) {
  const headers = { Accept: "application/json" };
  if (body !== undefined) headers["Content-Type"] = "application/json";
  if (token) headers.Authorization = `Bearer ${token}`;
  const response = await fetch(new URL(path.replace(/^\//, ""), SERVICE_ROOT), {
    method, headers, body: body === undefined ? undefined : JSON.stringify(body), signal, cache: "no-store",
  });
  const data = await response.json().catch(() => null);
  if (!response.ok) throw new ApiError(response.status, data);
  return data;
}

/** Service clock minus this device's clock [s], from /health's `now_unix_s` (0 if it says nothing). */
export async function clockOffset_s() {
  const sent_s = Date.now() / 1000;
  const health = await call("GET", "/health");
  const back_s = Date.now() / 1000;
  return Number.isFinite(health?.now_unix_s) ? health.now_unix_s - (sent_s + back_s) / 2 : 0;
}

const RETRY_SOCKET_S = [2, 5, 10, 30];

/**
 * One trip's fixes in, advisories out. `send(fix)` goes over the WebSocket when it is open, else as a REST
 * POST (one at a time; a newer fix replaces one still waiting). Every advisory, whichever way it came,
 * goes to `onAdvice`; transport changes and errors to `onLink(kind, detail)`. `down` says the service is out of
 * reach (the socket dropped, not by us; a REST call failed on the network or with a 5xx) until an advisory comes
 * again (`onLink("down", ...)` when it goes); `waiting_s()` how long the oldest fix sent has waited for its answer.
 */
export class TripLink {
  constructor(created, { onAdvice, onLink }) {
    this.trip = created;
    this.links = { stream: `/v1/trips/${created.trip_id}/stream`, fixes: `/v1/trips/${created.trip_id}/fixes`,
      end: `/v1/trips/${created.trip_id}/end`, audio: `/v1/trips/${created.trip_id}/advice.wav`, ...created.links };
    this.onAdvice = onAdvice;
    this.onLink = onLink;
    this.ws = null;
    this.closed = false;
    this.failures = 0;
    this.posting = false;
    this.waiting = null;
    this.unanswered = 0; // fixes sent on the socket, not answered yet
    this.sentAt = []; // when each of them was sent [performance.now() ms]
    this.postSince = null; // when the REST call in flight was made [ms]
    this.down = false;
    this.opened = new Promise((resolve) => { this.settleOpened = resolve; });
    this.connect();
  }

  get via() {
    return this.ws?.readyState === WebSocket.OPEN ? "websocket" : "rest";
  }

  connect() {
    if (this.closed) return;
    const url = new URL(this.links.stream.replace(/^\//, ""), SERVICE_ROOT);
    url.protocol = url.protocol === "https:" ? "wss:" : "ws:";
    url.searchParams.set("token", this.trip.token);
    let ws;
    try {
      ws = new WebSocket(url);
    } catch (error) {
      this.retrySocket(String(error));
      return;
    }
    this.ws = ws;
    ws.onopen = () => {
      ws.opened = true;
      this.failures = 0;
      this.settleOpened(true);
      this.onLink("websocket");
    };
    ws.onmessage = (event) => {
      this.unanswered = Math.max(0, this.unanswered - 1);
      this.sentAt.shift();
      this.down = false;
      let message;
      try {
        message = JSON.parse(event.data);
      } catch {
        return;
      }
      if (message && "error" in message) {
        this.onLink("error", message);
      } else {
        this.onAdvice(message);
      }
    };
    ws.onclose = (event) => {
      if (this.ws === ws) this.ws = null;
      this.unanswered = 0;
      this.sentAt = [];
      if (event.code === 4404 || event.code === 4401 || event.code === 4403) {
        this.onLink("ended", { status: event.code - 4000, message: event.reason });
        return;
      }
      this.retrySocket(`socket closed (${event.code})`);
      // the service went, or the network (not 4409: a newer socket of this trip replaced this one, the service is there)
      if (!this.closed && ws.opened && event.code !== 4409) this.lost(`socket closed (${event.code})`);
    };
  }

  retrySocket(why) {
    this.settleOpened(false);
    if (this.closed) return;
    const wait_s = RETRY_SOCKET_S[Math.min(this.failures, RETRY_SOCKET_S.length - 1)];
    this.failures += 1;
    this.onLink("rest", { message: `${why}; sending by REST, socket retried in ${wait_s} s` });
    setTimeout(() => this.connect(), wait_s * 1000);
  }

  /** Resolves once the first socket is open (true) or has failed (false), at most `limit_s` later. */
  ready(limit_s = 5) {
    return Promise.race([this.opened, new Promise((resolve) => setTimeout(() => resolve(false), limit_s * 1000))]);
  }

  /** The service is out of reach: said once until an advisory comes again. */
  lost(why) {
    if (this.down) return;
    this.down = true;
    this.onLink("down", { message: why });
  }

  /** Seconds the oldest fix sent has waited for its answer (0: none waits). */
  waiting_s() {
    const since = Math.min(this.sentAt[0] ?? Infinity, this.postSince ?? Infinity);
    return Number.isFinite(since) ? (performance.now() - since) / 1000 : 0;
  }

  send(fix) {
    if (this.closed) return;
    if (this.ws?.readyState === WebSocket.OPEN) {
      this.ws.send(JSON.stringify(fix));
      this.unanswered += 1;
      this.sentAt.push(performance.now());
      return;
    }
    this.waiting = fix;
    if (!this.posting) this.post();
  }

  async post() {
    this.posting = true;
    while (this.waiting && !this.closed) {
      const fix = this.waiting;
      this.waiting = null;
      this.postSince = performance.now();
      try {
        const advice = await call("POST", this.links.fixes, { body: fix, token: this.trip.token });
        this.down = false;
        this.onAdvice(advice);
      } catch (error) {
        if (error.status === 404) this.onLink("ended", { status: 404, message: error.message });
        else if (error.status === undefined || error.status >= 500) this.lost(error.message); // no answer, or the service failing
        else this.onLink("error", { status: error.status, message: error.message });
      } finally {
        this.postSince = null;
      }
    }
    this.posting = false;
  }

  /** Until every fix sent has its answer (at most `limit_s`). */
  async settled(limit_s = 3) {
    const deadline = Date.now() + limit_s * 1000;
    while ((this.unanswered > 0 || this.posting) && Date.now() < deadline) {
      await new Promise((resolve) => setTimeout(resolve, 50));
    }
  }

  /** End the trip (after the answers to the fixes already sent); resolves to its score (TripScoreOut). */
  async end() {
    await this.settled();
    this.closed = true;
    const ws = this.ws;
    this.ws = null;
    ws?.close(1000, "trip ended");
    return call("POST", this.links.end, { token: this.trip.token });
  }
}
