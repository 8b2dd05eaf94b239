"""Write the same drive (``replay/data/field_test_advised.csv``) as real phone apps export it.

``python -m tests.replay.make_phone_exports`` rewrites ``tests/replay/data/phone/`` (deterministic). Each file
follows its format's documentation, not our reader: the test (``test_phone_exports.py``) checks that
``replay`` scores every one of them like our own CSV.

| file | style |
|---|---|
| ``android_location_ms.csv`` | an Android app dumping ``Location``: ``getTime()`` epoch ms, ``getSpeed()`` m/s, ``getBearing()``, ``getAccuracy()`` |
| ``gpslogger.csv`` | GPSLogger for Android CSV: ISO ``time``, ``lat``, ``lon``, ``elevation``, ``accuracy``, ``bearing``, ``speed`` ..., ``timestamp_ms`` |
| ``sensor_logger_ns.csv`` | Sensor Logger ``Location.csv``: ``time`` epoch ns, ``seconds_elapsed``, ``speed``, ``bearing``, ``horizontalAccuracy``, ``longitude``, ``latitude`` |
| ``epoch_us.csv`` | a data logger with epoch microseconds and ``Speed (km/h)`` |
| ``excel_de.csv`` | a European spreadsheet: ``;``-separated, decimal comma, ``Latitude;Longitude;Speed (km/h);Course`` |
| ``osmand.gpx`` | OsmAnd GPX 1.1: ``<extensions><osmand:speed>``, ``<osmand:heading>``, ``<hdop>`` |
| ``gpslogger.gpx`` | GPSLogger GPX 1.1: ``<extensions><speed>``, ``<course>`` inside ``<trkpt>`` is GPX 1.0 only, so none |
| ``garmin.gpx`` | Garmin TrackPointExtension v2: ``<gpxtpx:TrackPointExtension><gpxtpx:speed>``, ``<gpxtpx:course>`` |
"""

from __future__ import annotations

import csv
from datetime import datetime, timezone
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
SOURCE = REPO / "replay" / "data" / "field_test_advised.csv"
OUT = Path(__file__).resolve().parent / "data" / "phone"


def _rows() -> list[dict[str, str]]:
    lines = [ln for ln in SOURCE.read_text().splitlines() if not ln.startswith("#")]
    return list(csv.DictReader(lines))


def _ms(iso: str) -> int:
    return round(datetime.fromisoformat(iso.replace("Z", "+00:00")).timestamp() * 1000)


def _iso(ms: int, digits: int = 3) -> str:
    stamp = datetime.fromtimestamp(ms / 1000, tz=timezone.utc)
    return stamp.isoformat(timespec="milliseconds").replace("+00:00", "Z") if digits == 3 else stamp.strftime("%Y-%m-%dT%H:%M:%SZ")


def _write(name: str, text: str) -> None:
    (OUT / name).write_text(text, encoding="utf-8", newline="")


def main() -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    rows = _rows()
    ms = [_ms(r["time"]) for r in rows]
    lat, lon, v, hdg, acc = ([r[k] for r in rows] for k in ("lat", "lon", "speed_mps", "heading_deg", "accuracy_m"))

    out = ["timestamp,latitude,longitude,altitude,speed,bearing,accuracy,provider"]
    out += [f"{t},{a},{o},35.0,{s},{h},{c},gps" for t, a, o, s, h, c in zip(ms, lat, lon, v, hdg, acc, strict=True)]
    _write("android_location_ms.csv", "\n".join(out) + "\n")

    head = "time,lat,lon,elevation,accuracy,bearing,speed,satellites,provider,hdop,vdop,pdop,geoidheight,ageofdgpsdata,dgpsid,activity,battery,annotation,timestamp_ms,time_offset,distance,starttimestamp_ms,profile_name,battery_charging"
    out = [head] + [
        f"{_iso(t)},{a},{o},35.0,{c},{h},{s},11,gps,0.8,1.1,1.4,47.0,,,,83,,{t},{_iso(t)},,{ms[0]},Default Profile,false"
        for t, a, o, s, h, c in zip(ms, lat, lon, v, hdg, acc, strict=True)
    ]
    _write("gpslogger.csv", "\r\n".join(out) + "\r\n")

    out = ["time,seconds_elapsed,bearingAccuracy,speedAccuracy,verticalAccuracy,horizontalAccuracy,speed,bearing,altitude,longitude,latitude"]
    out += [f"{t * 1_000_000},{(t - ms[0]) / 1000:.3f},10.0,0.5,3.0,{c},{s},{h},35.0,{o},{a}" for t, a, o, s, h, c in zip(ms, lat, lon, v, hdg, acc, strict=True)]
    _write("sensor_logger_ns.csv", "\n".join(out) + "\n")

    out = ["epoch_us,lat,lon,Speed (km/h),heading"]
    out += [f"{t * 1000},{a},{o},{float(s) * 3.6:.3f},{h}" for t, a, o, s, h in zip(ms, lat, lon, v, hdg, strict=True)]
    _write("epoch_us.csv", "\n".join(out) + "\n")

    def comma(x: str | float) -> str:
        return str(x).replace(".", ",")

    out = ["Time;Latitude;Longitude;Speed (km/h);Course;Accuracy"]
    out += [";".join([_iso(t), comma(a), comma(o), comma(f"{float(s) * 3.6:.2f}"), comma(h), comma(c)]) for t, a, o, s, h, c in zip(ms, lat, lon, v, hdg, acc, strict=True)]
    _write("excel_de.csv", "\r\n".join(out) + "\r\n")

    def gpx(creator: str, ns: str, point) -> str:
        pts = "\n".join(point(t, a, o, s, h, c) for t, a, o, s, h, c in zip(ms, lat, lon, v, hdg, acc, strict=True))
        return (f'<?xml version="1.0" encoding="UTF-8"?>\n<gpx version="1.1" creator="{creator}" xmlns="http://www.topografix.com/GPX/1/1" {ns}'
                f'xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" xsi:schemaLocation="http://www.topografix.com/GPX/1/1 http://www.topografix.com/GPX/1/1/gpx.xsd">\n'
                f"  <metadata><time>{_iso(ms[0], 0)}</time></metadata>\n  <trk>\n    <name>{creator} drive</name>\n    <trkseg>\n{pts}\n    </trkseg>\n  </trk>\n</gpx>\n")  # fmt: skip

    _write("osmand.gpx", gpx("OsmAnd~ 4.8.6", 'xmlns:osmand="https://osmand.net" ', lambda t, a, o, s, h, c: (
        f'      <trkpt lat="{a}" lon="{o}">\n        <ele>35.0</ele>\n        <time>{_iso(t)}</time>\n        <hdop>{float(c) / 5:.1f}</hdop>\n'
        f"        <extensions>\n          <osmand:speed>{s}</osmand:speed>\n          <osmand:heading>{h}</osmand:heading>\n        </extensions>\n      </trkpt>")))  # fmt: skip
    _write("gpslogger.gpx", gpx("GPSLogger 131 - http://gpslogger.mendhak.com/", "", lambda t, a, o, s, h, c: (
        f'      <trkpt lat="{a}" lon="{o}">\n        <ele>35.0</ele>\n        <time>{_iso(t)}</time>\n        <src>gps</src>\n        <sat>11</sat>\n'
        f"        <hdop>0.8</hdop>\n        <extensions>\n          <speed>{s}</speed>\n        </extensions>\n      </trkpt>")))  # fmt: skip
    _write("garmin.gpx", gpx("Garmin Connect", 'xmlns:gpxtpx="http://www.garmin.com/xmlschemas/TrackPointExtension/v2" ', lambda t, a, o, s, h, c: (
        f'      <trkpt lat="{a}" lon="{o}">\n        <ele>35.0</ele>\n        <time>{_iso(t, 0) if t % 1000 == 0 else _iso(t)}</time>\n        <extensions>\n'
        f"          <gpxtpx:TrackPointExtension>\n            <gpxtpx:speed>{s}</gpxtpx:speed>\n            <gpxtpx:course>{h}</gpxtpx:course>\n"
        f"          </gpxtpx:TrackPointExtension>\n        </extensions>\n      </trkpt>")))  # fmt: skip


if __name__ == "__main__":
    main()
