// Units of what the driver reads: speeds in km/h or mph, distances in m/km or ft/mi.
// The service speaks in its trip's units; the page shows numbers in the same units when the trip says
// which (`units` at trip creation), else in the user's choice, else in the locale's.

export const KMH_PER_MPS = 3.6;
export const MPH_PER_MPS = 1 / 0.44704; // international mile: 1609.344 m
export const FT_PER_M = 1 / 0.3048;
const M_PER_MI = 1609.344;

// Regions whose road signs give speeds in miles per hour (US and territories, UK and Crown dependencies,
// Liberia, Myanmar, and Caribbean/Pacific states that kept imperial road signs).
const MPH_REGIONS = new Set([
  "US", "PR", "VI", "GU", "AS", "MP", "UM", "GB", "IM", "JE", "GG", "LR", "MM", "AG", "BS", "BZ", "DM",
  "GD", "KN", "LC", "VC", "KY", "VG", "TC", "AI", "MS", "FK", "SH", "WS",
]);

/** "mph" | "kmh" from a units name the service or the user may use; null when not recognised. */
export function normalizeUnits(name) {
  if (typeof name !== "string") return null;
  const key = name.toLowerCase().replace(/[^a-z]/g, "");
  if (["mph", "imperial", "mih", "milesperhour"].includes(key)) return "mph";
  if (["kmh", "kph", "kmph", "metric", "si", "kilometersperhour", "kilometresperhour"].includes(key)) return "kmh";
  return null;
}

/** The units of a locale's roads: mph in the regions above, km/h elsewhere. */
export function localeUnits(locale) {
  let region;
  try {
    region = new Intl.Locale(locale).maximize().region;
  } catch {
    region = /[-_]([A-Za-z]{2})\b/.exec(String(locale))?.[1];
  }
  return MPH_REGIONS.has(String(region).toUpperCase()) ? "mph" : "kmh";
}

/**
 * Which units to show: the trip's (the service speaks in them: the corridor's default, or what the page
 * asked for at creation), else the user's choice, else the locale's.
 */
export function chooseUnits({ choice, trip, locale }) {
  return normalizeUnits(trip?.units) ?? normalizeUnits(choice) ?? localeUnits(locale);
}

/**
 * The value to send as `units` at trip creation for `units` ("mph" | "kmh"), given the service's JSON
 * schema of that field (OpenAPI); null when the service takes no `units` or none of its values fits.
 */
export function unitsParameter(schema, units) {
  if (!schema || typeof schema !== "object") return null;
  const values = [];
  const walk = (node) => {
    if (Array.isArray(node)) node.forEach(walk);
    else if (node && typeof node === "object") {
      if (Array.isArray(node.enum)) values.push(...node.enum);
      if (typeof node.const === "string") values.push(node.const);
      Object.values(node).forEach(walk);
    }
  };
  walk(schema);
  if (values.length === 0) return units;
  return values.find((value) => normalizeUnits(value) === units) ?? null;
}

/**
 * A speed in whole units, as the service speaks it (`advisory.advice.wording.spoken_speed`, the same
 * operations): down to 0.01 m/s as the API publishes it (a no-op on its numbers), converted, halves up.
 */
export function speedIn(speed_mps, units) {
  if (speed_mps == null || !Number.isFinite(speed_mps)) return null;
  return Math.round((Math.floor(speed_mps * 100 + 1e-9) / 100) * (units === "mph" ? MPH_PER_MPS : KMH_PER_MPS));
}

export function speedUnitLabel(units) {
  return units === "mph" ? "mph" : "km/h";
}

/** A distance for a glance: metres (5 m steps) or feet (10 ft steps) up close, km or mi farther. */
export function distanceText(distance_m, units, locale) {
  if (distance_m == null || !Number.isFinite(distance_m)) return "–";
  const one = new Intl.NumberFormat(locale, { maximumFractionDigits: 1, minimumFractionDigits: 1 });
  if (units === "mph") {
    if (distance_m < 0.1 * M_PER_MI) return `${Math.round((distance_m * FT_PER_M) / 10) * 10} ft`;
    return `${one.format(distance_m / M_PER_MI)} mi`;
  }
  if (distance_m < 1000) return `${Math.round(distance_m / 5) * 5} m`;
  return `${one.format(distance_m / 1000)} km`;
}
