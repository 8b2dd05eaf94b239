// A recorded GPS trace (the CSV format `replay` reads, docs/REPLAY.md) and its demo-drive timeline.

const COLUMNS = {
  time: ["time", "timestamp", "t_unix_s", "t_s"],
  lat: ["lat", "lat_deg", "latitude"],
  lon: ["lon", "lon_deg", "lng", "longitude"],
  speed: ["speed_mps"],
  heading: ["heading_deg", "heading", "course_deg"],
  accuracy: ["accuracy_m", "accuracy", "hacc_m"],
};

function column(names, header) {
  const i = header.findIndex((name) => names.includes(name.trim().toLowerCase()));
  return i < 0 ? null : i;
}

function number(text) {
  const trimmed = (text ?? "").trim();
  if (trimmed === "") return null;
  const x = Number(trimmed);
  return Number.isFinite(x) ? x : NaN;
}

/**
 * Parse a GPS trace CSV: `# key: value` header lines (corridor, timing, entry_unix_s, vehicle), then a
 * header row and one fix per row. Times are ISO 8601 or Unix seconds. Throws an Error naming the line.
 * Returns {meta, fixes: [{t_unix_s, lat_deg, lon_deg, speed_mps?, heading_deg?, accuracy_m?}]}.
 */
export function parseTraceCsv(text) {
  const meta = {};
  const fixes = [];
  let header = null;
  let cols = null;
  const lines = text.split(/\r?\n/);
  lines.forEach((raw, index) => {
    const line = raw.trim();
    const where = `line ${index + 1}`;
    if (line === "") return;
    if (line.startsWith("#")) {
      const m = /^#\s*([A-Za-z_]+)\s*:\s*(.*)$/.exec(line);
      if (m && header === null) meta[m[1]] = m[2].trim();
      return;
    }
    const cells = line.split(",");
    if (header === null) {
      header = cells;
      cols = Object.fromEntries(Object.entries(COLUMNS).map(([key, names]) => [key, column(names, header)]));
      for (const key of ["time", "lat", "lon"]) {
        if (cols[key] === null) throw new Error(`${where}: no ${key} column (one of ${COLUMNS[key].join(", ")})`);
      }
      return;
    }
    const timeText = cells[cols.time]?.trim() ?? "";
    const t = /^-?[\d.]+$/.test(timeText) ? Number(timeText) : Date.parse(timeText) / 1000;
    const fix = { t_unix_s: t, lat_deg: number(cells[cols.lat]), lon_deg: number(cells[cols.lon]) };
    if (!Number.isFinite(t)) throw new Error(`${where}: time ${JSON.stringify(timeText)} is not ISO 8601 or Unix seconds`);
    if (!(Math.abs(fix.lat_deg) <= 90) || !(Math.abs(fix.lon_deg) <= 180)) throw new Error(`${where}: latitude/longitude missing or out of range`);
    for (const [key, field] of [["speed", "speed_mps"], ["heading", "heading_deg"], ["accuracy", "accuracy_m"]]) {
      if (cols[key] === null) continue;
      const x = number(cells[cols[key]]);
      if (Number.isNaN(x)) throw new Error(`${where}: ${header[cols[key]]} is not a number`);
      if (x !== null) fix[field] = x;
    }
    if (fixes.length && t <= fixes[fixes.length - 1].t_unix_s) throw new Error(`${where}: time does not increase`);
    fixes.push(fix);
  });
  if (fixes.length < 2) throw new Error("the trace has fewer than two fixes");
  if (meta.entry_unix_s !== undefined) meta.entry_unix_s = Number(meta.entry_unix_s);
  return { meta, fixes };
}

/**
 * The demo drive's timeline: the trace's times moved onto the service's clock, played `pace` times faster.
 *
 * Fix i is sent `(t_i - t_0) / pace` seconds after the start, stamped `t_i + shift_s`, with
 * `shift_s = now_s - t_0 - duration_s * (1 - 1 / pace)`: at pace 1 a fix is stamped when it is sent; faster,
 * every stamp is at or before its sending instant and the last one lands on it, so no fix is ever ahead of
 * the service's clock and none is older than the trace's duration. The signal timing follows the trace's
 * (the trip is created with its timing preset and `entry_unix_s + shift_s`), so the lights change where
 * they did on the recorded drive.
 */
export function demoTimeline(trace, now_s, pace = 1) {
  const { fixes, meta } = trace;
  const t0 = fixes[0].t_unix_s;
  const duration_s = fixes[fixes.length - 1].t_unix_s - t0;
  const shift_s = now_s - t0 - duration_s * (1 - 1 / pace);
  return {
    entry_unix_s: Number.isFinite(meta.entry_unix_s) ? meta.entry_unix_s + shift_s : undefined,
    steps: fixes.map((fix) => ({ delay_s: (fix.t_unix_s - t0) / pace, fix: { ...fix, t_unix_s: fix.t_unix_s + shift_s } })),
  };
}
