// The phone's GPS (Geolocation API) as the service's fixes, at most one a second.

export const FIX_PERIOD_S = 1;

/** A service fix from a W3C GeolocationPosition; times moved onto the service's clock by `offset_s`. */
export function fixFromPosition(position, offset_s = 0) {
  const c = position.coords;
  const fix = { t_unix_s: position.timestamp / 1000 + offset_s, lat_deg: c.latitude, lon_deg: c.longitude };
  if (c.speed != null && Number.isFinite(c.speed) && c.speed >= 0) fix.speed_mps = Math.min(c.speed, 70);
  if (c.heading != null && Number.isFinite(c.heading) && c.speed !== 0) fix.heading_deg = ((c.heading % 360) + 360) % 360;
  if (c.accuracy != null && Number.isFinite(c.accuracy) && c.accuracy >= 0) fix.accuracy_m = Math.min(c.accuracy, 100000);
  if (c.altitude != null && Number.isFinite(c.altitude) && c.altitude >= -1000 && c.altitude <= 10000) fix.altitude_m = c.altitude;
  if (c.altitudeAccuracy != null && Number.isFinite(c.altitudeAccuracy) && c.altitudeAccuracy >= 0) fix.altitude_accuracy_m = Math.min(c.altitudeAccuracy, 100000);
  return fix;
}

/**
 * Watch the position and call `onFix(fix)` at most once per FIX_PERIOD_S (the newest position; one that
 * arrives early waits for its slot). Returns a function that stops watching. `onError(message)` on
 * refusal or loss of signal, `onError(null)` when positions come again.
 */
export function watchFixes({ offset_s = 0, onFix, onError }) {
  if (!("geolocation" in navigator)) {
    onError(window.isSecureContext ? "this browser has no GPS access" : "GPS needs a secure page: open the app over https:// (or on localhost)");
    return () => {};
  }
  let lastSent_ms = -Infinity;
  let pending = null;
  let timer = null;
  let lastStamp = -Infinity;
  let failing = false;
  const flush = () => {
    timer = null;
    if (!pending) return;
    lastSent_ms = performance.now();
    const fix = pending;
    pending = null;
    onFix(fix);
  };
  const id = navigator.geolocation.watchPosition(
    (position) => {
      if (failing) onError(null);
      failing = false;
      const fix = fixFromPosition(position, offset_s);
      if (fix.t_unix_s <= lastStamp) return; // a repeated position
      lastStamp = fix.t_unix_s;
      pending = fix;
      const wait_ms = lastSent_ms + FIX_PERIOD_S * 1000 - performance.now();
      if (wait_ms <= 50) flush();
      else if (timer === null) timer = setTimeout(flush, wait_ms);
    },
    (error) => {
      failing = true;
      onError(error.code === 1 ? "GPS permission refused: allow location for this page"
        : error.code === 3 ? "GPS: no position for 15 s" : `GPS: ${error.message || "position unavailable"}`);
    },
    { enableHighAccuracy: true, maximumAge: 0, timeout: 15000 },
  );
  return () => {
    navigator.geolocation.clearWatch(id);
    if (timer !== null) clearTimeout(timer);
  };
}
