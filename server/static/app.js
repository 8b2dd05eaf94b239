// The phone app: pick a road, start a trip, send GPS (or a recorded demo drive) at 1 Hz, show and speak
// each advisory, end the trip and show its score beside the regular driver's. docs/APP.md.

import { call, clockOffset_s, SERVICE_ROOT, TripLink } from "./lib/api.js";
import { watchFixes } from "./lib/gps.js";
import { Speaker } from "./lib/speech.js";
import { demoTimeline, parseTraceCsv } from "./lib/trace.js";
import { chooseUnits, distanceText, normalizeUnits, speedIn, speedUnitLabel, unitsParameter } from "./lib/units.js";

const DEMO_TRACE_URL = "demo/field_test_advised.csv";
const END_FIXES = 3; // the trip ends by itself this many fixes after the car reaches the corridor's end
const ANSWER_LIMIT_S = 1.5; // a fix unanswered this long: the service is out of reach (a killed one: at once, the socket drops)
const LOST_MESSAGE = "Connection to the service lost. Advice paused.";
const TRIP_LOST = "The service restarted and did not keep this trip (it kept its trips in memory only): no score for this drive. Start a new trip for advice.";
const THEMES = ["auto", "dark", "light"];
const ACTIONS = {
  cruise: "Hold your speed", ease_off: "Ease off", coast: "Coast", slow_down: "Slow down", brake_to: "Brake",
  accelerate: "Speed up", stop: "Prepare to stop", resume: "Resume", none: "No advice",
};
const REASONS = { traffic_behind: "Keep up with traffic", queue: "Queue ahead" }; // a speed given for the traffic, not for the light
const PAUSES = {
  no_fix: "Waiting for GPS", no_speed: "Waiting for speed", poor_gps: "GPS weak", off_route: "Off the route",
  no_spat: "No signal data", stale_spat: "Signal data old", low_confidence: "Timing uncertain",
  too_close: "At the light", short_wait: "Short wait", tight_green: "Drive normally", far_ahead: "Light far ahead",
};

const $ = (id) => document.getElementById(id);
const query = new URLSearchParams(location.search);
const locale = navigator.language || "en";
const store = {
  get: (key, fallback) => { try { return localStorage.getItem(`ecodrive.${key}`) ?? fallback; } catch { return fallback; } },
  set: (key, value) => { try { localStorage.setItem(`ecodrive.${key}`, value); } catch { /* private mode */ } },
};

/** This phone's id, random and kept (`device_id` of every trip it starts): the service limits one device's open
 * trips within its API key's quota (docs/SERVICE.md, "Who may create trips"). */
function deviceId() {
  let id = store.get("device", "");
  if (!/^[A-Za-z0-9._:-]{8,64}$/.test(id)) {
    const bytes = crypto.getRandomValues(new Uint8Array(16)); // also on a plain-http page, unlike randomUUID
    id = "web-" + Array.from(bytes, (b) => b.toString(16).padStart(2, "0")).join("");
    store.set("device", id);
  }
  return id;
}

const speaker = new Speaker({ lang: document.documentElement.lang || locale, onState: (text) => note(text) });
const corridors = new Map(); // name -> CorridorSummary
let drive = null; // the trip under way: {link, trip, units, names, stop, endFixes, wasBeforeEnd, ...}
let wakeLock = null;

// -- small helpers ---------------------------------------------------------------------------------
function show(state) {
  document.body.dataset.state = state;
  for (const id of ["setup", "drive", "score"]) $(id).hidden = id !== (state === "starting" ? "setup" : state);
  $("start").disabled = $("demo").disabled = state === "starting";
}

function note(text) {
  $("status").textContent = text;
}

function setText(id, text) {
  const el = $(id);
  if (el.textContent !== text) el.textContent = text;
}

function capitalise(text) {
  return text ? text[0].toUpperCase() + text.slice(1) : text;
}

/** A light's name from the corridor's list ("light 7001" until the list has come). */
function lightName(current, id) {
  return capitalise(current.names.get(id) ?? `light ${id}`);
}

// -- settings: theme, mute, units, pace ------------------------------------------------------------
function applyTheme(theme) {
  document.documentElement.dataset.theme = theme;
  $("theme").textContent = capitalise(theme);
  store.set("theme", theme);
}

function applyMute(muted) {
  speaker.setMuted(muted);
  $("mute").setAttribute("aria-pressed", String(muted));
  $("mute").textContent = muted ? "Muted" : "Sound on";
  store.set("muted", muted ? "1" : "0");
}

// -- screen wake lock (degrades to nothing where unsupported or refused) ---------------------------
async function keepAwake() {
  if (!("wakeLock" in navigator)) return "screen may sleep (no wake lock here)";
  try {
    wakeLock = await navigator.wakeLock.request("screen");
    return "screen kept on";
  } catch (error) {
    return `screen may sleep (${error.name})`;
  }
}

document.addEventListener("visibilitychange", () => {
  if (drive && document.visibilityState === "visible" && wakeLock?.released !== false) keepAwake();
});

// -- a trip: start, advice in, end -----------------------------------------------------------------
async function start(mode) {
  if (!speaker.muted) speaker.unlock(); // inside the tap: browsers allow speech and sound only after a user gesture
  const awake = keepAwake();
  show("starting");
  note("");
  setText("setup-error", "");
  try {
    const offset_s = await clockOffset_s().catch(() => 0);
    let body = { corridor: $("corridor").value || undefined };
    let timeline = null;
    if (mode === "demo") {
      const response = await fetch(DEMO_TRACE_URL, { cache: "no-store" });
      if (!response.ok) throw new Error(`the demo trace is not available (HTTP ${response.status})`);
      const trace = parseTraceCsv(await response.text());
      const pace = Math.max(1, Number($("pace").value) || 1);
      timeline = demoTimeline(trace, Date.now() / 1000 + offset_s, pace);
      const { corridor, timing, vehicle } = trace.meta;
      body = { corridor, timing, vehicle, entry_unix_s: timeline.entry_unix_s };
    }
    const chosen = normalizeUnits($("units").value);
    if (chosen) { // the user's units: asked of the service too, where it takes them, so that it speaks them
      const spec = await call("GET", "/openapi.json").catch(() => null);
      const units = unitsParameter(spec?.components?.schemas?.TripCreate?.properties?.units, chosen);
      if (units !== null) body.units = units;
    }
    body.device_id = deviceId();
    const key = $("api-key").value.trim();
    let created;
    try {
      created = await call("POST", "/v1/trips", { body, token: key || undefined });
    } catch (error) {
      if (error.status === 401 || error.status === 403) $("key-row").hidden = false;
      throw error;
    }
    if (key) store.set("apiKey", key);
    const corridor = corridors.get(created.corridor);
    const names = new Map();
    call("GET", `/v1/corridors/${encodeURIComponent(created.corridor)}/intersections`)
      .then((list) => list.forEach((ix) => names.set(ix.id, ix.name)))
      .catch(() => {});
    const current = {
      mode, trip: created, names, endFixes: 0, wasBeforeEnd: false, ended: false, stop: () => {},
      length_m: corridor?.length_m, units: chooseUnits({ choice: $("units").value, trip: created, locale }),
    };
    current.link = new TripLink(created, {
      onAdvice: (advice) => drive === current && render(advice),
      onLink: (kind, detail) => drive === current && onLink(kind, detail),
    });
    // the service out of reach (a fix unanswered too long; a dropped socket or a failed call say so at once)
    current.watch = setInterval(() => {
      if (drive === current && !current.lost && current.link.waiting_s() > ANSWER_LIMIT_S) serviceLost(current, "no answer from the service");
    }, 200);
    speaker.wav = () => fetch(new URL(current.link.links.audio.replace(/^\//, ""), SERVICE_ROOT), {
      headers: { Authorization: `Bearer ${created.token}` }, cache: "no-store",
    });
    drive = current;
    document.body.dataset.trip = created.trip_id;
    document.body.dataset.units = current.units;
    resetDrive(current);
    show("drive");
    awake.then((text) => { current.awake = text; });
    await current.link.ready(); // the socket open (or failed: REST), so that no fix waits
    if (current.ended) return;
    current.stop = mode === "demo" ? play(timeline, current) : watchFixes({
      offset_s, onFix: (fix) => current.link.send(fix), onError: (text) => note(text ?? ""),
    });
  } catch (error) {
    setText("setup-error", `Could not start: ${error.message}`);
    show("setup");
    wakeLock?.release().catch(() => {});
  }
}

/** The demo drive: the recorded fixes at their (paced) instants, through the trip's link. */
function play(timeline, current) {
  const t0_ms = performance.now();
  let timer = null;
  let i = 0;
  const next = () => {
    while (i < timeline.steps.length && performance.now() - t0_ms >= timeline.steps[i].delay_s * 1000) {
      current.link.send(timeline.steps[i].fix);
      i += 1;
    }
    if (i >= timeline.steps.length) {
      finish(current, "the recorded drive is over");
      return;
    }
    timer = setTimeout(next, Math.max(0, t0_ms + timeline.steps[i].delay_s * 1000 - performance.now()));
  };
  next();
  return () => clearTimeout(timer);
}

function onLink(kind, detail) {
  if (kind === "ended") {
    // after an outage: the service came back without the trip (it kept its trips in memory); else it ended it
    note(drive.wasLost ? "the service restarted without this trip" : "the service ended this trip");
    finish(drive, drive.wasLost ? "trip lost in the restart" : "ended by the service", { scored: false, summary: drive.wasLost ? TRIP_LOST : null });
  } else if (kind === "down") {
    serviceLost(drive, detail?.message);
  } else if (kind === "error" || kind === "rest") {
    note(detail?.message ?? kind);
  } else {
    note("");
  }
}

function resetDrive(current) {
  for (const key of ["stale", "staleSince", "recovered"]) delete document.body.dataset[key];
  setText("target", "–");
  $("target").className = "big empty";
  setText("target-unit", "");
  setText("action", current.mode === "demo" ? "Demo drive" : "Waiting for GPS");
  $("action").dataset.action = "none";
  setText("message", "");
  setText("speed", "–");
  setText("distance", "–");
  setText("next-name", "Next light");
  setText("fresh", "–");
  $("fresh").dataset.fresh = "none";
  $("light").dataset.color = "none";
  setText("countdown", "");
  setText("countdown-label", "");
  setText("countdown-light", "");
  setText("link", "");
  $("drive").dataset.seq = "0";
}

/**
 * The service is out of reach: the screen says so at once (greyed, the lamp hatched, no countdown, "No
 * connection"), and the voice once; the trip goes on when the service answers again (`render`).
 */
function serviceLost(current, why) {
  if (!current || current.lost || current.ended) return;
  current.lost = current.wasLost = true;
  document.body.dataset.stale = "1";
  document.body.dataset.staleSince = String(Date.now() / 1000);
  $("light").dataset.color = "unknown";
  $("light").dataset.lightId = "";
  setText("countdown", "");
  setText("countdown-label", "no service");
  setText("countdown-light", "");
  $("action").dataset.action = "none";
  setText("action", "No connection");
  setText("message", LOST_MESSAGE);
  $("fresh").dataset.fresh = "lost";
  setText("fresh", "no service");
  setText("link", `no service · fix ${$("drive").dataset.seq}`);
  note(`service out of reach${why ? ` (${why})` : ""}: advice paused`);
  speaker.alert(LOST_MESSAGE);
}

/** One advisory on screen (and in the ear when `speak` is set). Tolerates fields it does not know. */
function render(a) {
  const current = drive;
  if (current.lost) { // the service answers again: the same trip, kept by it
    current.lost = false;
    current.recovered = (current.recovered ?? 0) + 1;
    delete document.body.dataset.stale;
    document.body.dataset.recovered = String(current.recovered);
    note("service back: trip kept");
  }
  const units = current.units;
  const unit = speedUnitLabel(units);
  $("drive").dataset.seq = String(a.seq ?? 0);
  $("drive").dataset.reason = a.reason ?? "";

  const target = speedIn(a.target_speed_mps, units);
  const stopping = a.action === "stop";
  setText("target", stopping ? "STOP" : target === null ? "–" : String(target));
  $("target").classList.toggle("word", stopping);
  $("target").classList.toggle("empty", !stopping && target === null);
  setText("target-unit", stopping || target === null ? "" : unit);
  $("action").dataset.action = a.action ?? "none";
  setText("action", a.action === "none" || !a.action ? (PAUSES[a.reason] ?? ACTIONS.none)
    : (REASONS[a.reason] ?? ACTIONS[a.action] ?? capitalise(a.action.replace(/_/g, " "))));
  setText("message", a.message ?? "");

  const speed = speedIn(a.speed_mps, units);
  setText("speed", speed === null ? "–" : `${speed} ${unit}`);
  // the light the advice is about: the next one, or the one after it when that one binds (the message then says
  // "Second light: ..."); an older service names none: the next light. The tile names it too, with its distance
  const lightId = a.light_red == null ? null : a.light_intersection_id ?? a.next_intersection_id;
  const tileId = lightId ?? a.next_intersection_id;
  const second = tileId != null && a.next_intersection_id != null && tileId !== a.next_intersection_id;
  const tileDistance = lightId != null && a.light_distance_m != null ? a.light_distance_m : a.distance_to_line_m;
  $("next-name").parentElement.dataset.lightId = tileId == null ? "" : String(tileId);
  setText("next-name", tileId == null ? "Next light" : `${second ? "Second light: " : ""}${lightName(current, tileId)}`);
  setText("distance", tileId == null ? (a.reason === "past_lights" ? "all passed" : "–") : distanceText(tileDistance, units, locale));

  const fresh = a.spat_fresh === true ? "yes" : a.spat_fresh === false ? "no" : "none";
  $("fresh").dataset.fresh = fresh;
  setText("fresh", { yes: "live", no: "out of date", none: "–" }[fresh]);

  // that light's colour now and the seconds to its next change, saying to which change and of which light (only
  // from fresh SPaT)
  const light = a.light_red == null || fresh === "no" ? "none" : a.light_red ? "red" : "green";
  $("light").dataset.color = fresh === "no" ? "unknown" : light;
  $("light").dataset.lightId = light === "none" || lightId == null ? "" : String(lightId);
  const seconds = a.seconds_to_change_s;
  const to = a.counts_down_to ?? (light === "red" ? "green" : "red");
  const counting = light !== "none" && Number.isFinite(seconds);
  setText("countdown", counting ? String(Math.max(0, Math.round(seconds))) : "");
  setText("countdown-label", counting ? `s to ${to}` : fresh === "no" ? "signal data out of date" : "");
  setText("countdown-light", light === "none" || lightId == null ? "" : lightName(current, lightId));

  setText("link", [current.link.via === "websocket" ? "WebSocket" : "REST", `fix ${a.seq ?? 0}`, speaker.muted ? "muted" : speaker.engine, current.awake]
    .filter(Boolean).join(" · "));

  if (a.speak && a.fix_status === "ok") speaker.say(a.message);

  // the end of the road ends the trip (after a few fixes there), if the car drove some of it
  if (Number.isFinite(current.length_m) && Number.isFinite(a.station_m) && a.fix_status === "ok") {
    if (a.station_m < current.length_m - 1) current.wasBeforeEnd = true;
    else if (current.wasBeforeEnd && (current.endFixes += 1) >= END_FIXES) finish(current, "end of the road");
  }
}

async function finish(current, why, { scored = true, summary = null } = {}) {
  if (!current || current.ended) return;
  current.ended = true;
  current.summary = summary;
  clearInterval(current.watch);
  current.stop();
  speaker.stop();
  note(why);
  let score = null;
  try {
    score = scored ? await current.link.end() : null;
  } catch (error) {
    note(`no score: ${error.message}`);
  }
  wakeLock?.release().catch(() => {});
  wakeLock = null;
  if (drive !== current) return;
  drive = null;
  renderScore(score, current);
  show("score");
}

// -- the score -------------------------------------------------------------------------------------
function renderScore(score, current) {
  const pct = new Intl.NumberFormat(locale, { style: "percent", maximumFractionDigits: 0 });
  const usd = new Intl.NumberFormat(locale, { style: "currency", currency: "USD", currencyDisplay: "narrowSymbol", maximumSignificantDigits: 2 });
  const wh = new Intl.NumberFormat(locale, { maximumFractionDigits: 0 });
  const you = score?.driven;
  const reg = score?.regular;
  const saved = score?.savings_frac ?? {};
  const rows = {
    energy: [(d) => `${wh.format(d.energy_kwh * 1000)} Wh`, saved.energy],
    wear: [(d) => usd.format(d.wear_usd), saved.wear],
    cost: [(d) => usd.format(d.cost_usd), saved.cost],
    time: [(d) => `${Math.round(d.duration_s)} s`, null],
  };
  for (const [key, [format, frac]] of Object.entries(rows)) {
    const cells = document.querySelectorAll(`#score-table tr[data-key="${key}"] td`);
    cells[0].textContent = you ? format(you) : "–";
    cells[1].textContent = reg ? format(reg) : "–";
    cells[2].textContent = Number.isFinite(frac) ? pct.format(frac) : key === "time" && you && reg ? `${Math.round(reg.duration_s - you.duration_s)} s` : "";
    cells[2].classList.toggle("worse", Number.isFinite(frac) ? frac < 0 : key === "time" && you && reg && you.duration_s > reg.duration_s);
  }
  let summary = current?.summary ?? "No score: the trip could not be ended.";
  if (score && you && Number.isFinite(saved.energy)) {
    const frac = Math.abs(saved.energy);
    // a trip ended early is scored over the distance it drove, the regular driver over the same distance
    const partial = Number.isFinite(score.compared_m) && Number.isFinite(current?.length_m) && score.compared_m < current.length_m - 0.5;
    const over = partial ? ` over the same ${distanceText(score.compared_m, current.units, locale)} (the trip ended before the end of the road).`
      : score.complete ? "." : " (indicative: the drive did not start at the start of the road).";
    summary = `You used ${pct.format(frac)} ${saved.energy >= 0 ? "less" : "more"} energy than a regular driver${over}`;
  } else if (score && you && score.red_light_crossings?.length) {
    summary = "A red light was crossed: this drive is not scored as a saving.";
  } else if (score && you) {
    summary = "Scored, but not compared with the regular driver.";
  } else if (score) {
    summary = "Not enough of the drive to score it.";
  }
  setText("score-summary", summary);
  $("score").dataset.complete = String(Boolean(score?.complete));
  $("score").dataset.energySaved = Number.isFinite(saved.energy) ? String(saved.energy) : "";
  setText("score-note", score?.note ? capitalise(score.note) + "." : "");
}

/** What the chosen road is, in the corridor's own words (a test track says so: its lights and limit are not the street's). */
function describeCorridor() {
  setText("corridor-note", corridors.get($("corridor").value)?.description ?? "");
}

// -- start-up --------------------------------------------------------------------------------------
async function init() {
  applyTheme(THEMES.includes(store.get("theme")) ? store.get("theme") : "auto");
  applyMute(store.get("muted") === "1");
  $("units").value = ["auto", "kmh", "mph"].includes(store.get("units")) ? store.get("units") : "auto";
  const pace = query.get("pace") ?? store.get("pace", "1");
  if (![...$("pace").options].some((o) => o.value === pace) && Number(pace) >= 1) $("pace").add(new Option(`${pace}×`, pace));
  $("pace").value = pace;
  $("api-key").value = store.get("apiKey", "");

  $("theme").addEventListener("click", () => applyTheme(THEMES[(THEMES.indexOf(document.documentElement.dataset.theme) + 1) % THEMES.length]));
  $("mute").addEventListener("click", () => {
    applyMute(!speaker.muted);
    if (!speaker.muted) speaker.unlock();
  });
  $("units").addEventListener("change", () => store.set("units", $("units").value));
  $("pace").addEventListener("change", () => store.set("pace", $("pace").value));
  $("corridor").addEventListener("change", () => {
    store.set("corridor", $("corridor").value);
    describeCorridor();
  });
  $("start").addEventListener("click", () => start("gps"));
  $("demo").addEventListener("click", () => start("demo"));
  $("end").addEventListener("click", () => finish(drive, "trip ended"));
  $("again").addEventListener("click", () => show("setup"));

  if (!window.isSecureContext || !("geolocation" in navigator)) {
    $("gps-note").hidden = false;
    $("gps-note").textContent = "GPS needs a secure page: open the app over https:// (or on this computer as localhost). The demo drive works anywhere.";
  }
  try {
    for (const c of await call("GET", "/v1/corridors")) {
      corridors.set(c.name, c);
      $("corridor").add(new Option(`${c.name} (${Math.round(c.length_m)} m, ${c.intersection_ids?.length ?? "?"} lights)`, c.name));
    }
    const saved = store.get("corridor", "");
    if (corridors.has(saved)) $("corridor").value = saved;
    describeCorridor();
  } catch (error) {
    setText("setup-error", `The service did not answer: ${error.message}`);
  }
  document.body.dataset.ready = "1";
  show("setup");
}

init();
