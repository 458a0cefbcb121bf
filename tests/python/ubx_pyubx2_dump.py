"""Decodes u-blox captures with pyubx2 (PyPI) and prints its view of every UBX frame, one JSON
object per line, for the cross-check in tests/tests/drivers/ubx_pyubx2.rs.

    python3 ubx_pyubx2_dump.py CAPTURE...

Each CAPTURE is a gpsd regression log (shared/corpora/gpsd-ubx/*.log): the leading lines that
start with `#` are gpsd's comments, not receiver bytes, and are skipped as navsync's capture
replay skips them (`drivers/src/gnss/capture.rs`); byte offsets count from the first byte after
them. The rest goes through pyubx2's own stream framing (`UBXReader`, UBX only, errors ignored:
NMEA/RTCM3 and truncated frames are skipped as pyubx2 skips them). Every UBX frame it delivers
is printed as

    {"capture", "offset", "class", "id", "length", "checksum_ok"}                 always
    {"index", "identity", "fields"} or {"index", "identity", "error"}          checksum ok

- `offset`: stream offset of the frame's 0xB5 (the pairing key of the Rust test, which knows
  the offset of every frame navsync's framer delivers);
- `index`: the frame's index among the UBX frames with a valid checksum of this capture;
- `identity`: pyubx2's name (`NAV-PVT`, ...); `error`: why pyubx2 could not parse it;
- `fields`: for the messages navsync decodes (NAV-PVT, -SOL, -TIMEGPS, -POSLLH, -VELNED, -DOP,
  -STATUS, -TIMEUTC, -SAT, -SVINFO, -EOE, TIM-TP, -TM2, RXM-RAWX, -SFRBX, ESF-MEAS, -RAW,
  HNR-PVT, MON-VER, ACK-ACK/NAK) pyubx2's values under the names and in the units of navsync's
  structs (`drivers/src/gnss/ubx/*.rs`): `height_m` is pyubx2's `height` (mm) / 1000, and so
  on. Repeated blocks are flattened as `sats[3].cno_dbhz`. Bit fields are parsed by pyubx2 both
  ways (`parsebitfield=2`): the whole flag bytes are printed as integers (navsync keeps them
  raw), and names ending in `()` are navsync's accessor methods, given pyubx2's single bits.

Conversions that are more than a unit change, each marked `# conv:` below: pyubx2's ESF-MEAS
has no `calibTtag` (its variable group shows it as one more `data` block); ESF-RAW's `data`
and `sTag` are raw X4 bytes, split here as the protocol specifies; NAV-SVINFO's legacy
satellite numbers are mapped to gnssId/svId with the protocol's table (written here again,
not taken from navsync); RXM-RAWX's `version` is the first byte of what pyubx2 calls
`reserved1`; the standard deviations are scaled by the protocol's formulas, which pyubx2
leaves to the caller. ESF data fields stay pyubx2's unsigned 24 bits (the Rust test names
that difference).

Needs pyubx2 (tested with 1.4.0, pinned by the Rust test).
"""

import io
import json
import math
import os
import sys

from pyubx2 import ERR_IGNORE, GET, PARSE_NONE, UBX_PROTOCOL, VALCKSUM, UBXReader
from pyubx2.ubxhelpers import calc_checksum


def le(b):
    """A bit field pyubx2 gives as bytes, as the little-endian integer navsync keeps."""
    return int.from_bytes(b, "little")


def g(m, name, i):
    """Attribute `name` of repeated block `i` (1-based, pyubx2's `_NN` suffix)."""
    return getattr(m, f"{name}_{i:02d}")


def text(b):
    """A NUL-padded character field up to its first NUL (navsync's `MonVer::text`)."""
    return b.split(b"\0", 1)[0].decode("ascii", "replace")


def legacy_sv(svid):
    """u-blox legacy satellite number -> (gnssId, svId), M8 protocol appendix "Satellite
    Numbering"; None outside the assigned ranges."""
    for lo, hi, gnss, base in (
        (1, 32, 0, 0),  # GPS
        (33, 64, 3, 27),  # BeiDou 6..37
        (65, 96, 6, 64),  # GLONASS 1..32
        (120, 158, 1, 0),  # SBAS
        (159, 163, 3, 158),  # BeiDou 1..5
        (173, 182, 4, 172),  # IMES 1..10
        (193, 202, 5, 192),  # QZSS 1..10
        (211, 246, 2, 210),  # Galileo 1..36
    ):
        if lo <= svid <= hi:
            return gnss, svid - base
    if svid == 255:  # GLONASS, slot unknown
        return 6, 255
    return None


def nav_pvt(m):
    f = {
        "itow_ms": m.iTOW,
        "year": m.year,
        "month": m.month,
        "day": m.day,
        "hour": m.hour,
        "min": m.min,
        "sec": m.second,
        "valid": le(m.valid),
        "t_acc_ns": m.tAcc,
        "nano_ns": m.nano,
        "fix_type": m.fixType,
        "flags": le(m.flags),
        "flags2": le(m.flags2),
        "num_sv": m.numSV,
        "lon_deg": m.lon,
        "lat_deg": m.lat,
        "height_m": m.height / 1e3,
        "h_msl_m": m.hMSL / 1e3,
        "h_acc_m": m.hAcc / 1e3,
        "v_acc_m": m.vAcc / 1e3,
        "vel_n_mps": m.velN / 1e3,
        "vel_e_mps": m.velE / 1e3,
        "vel_d_mps": m.velD / 1e3,
        "g_speed_mps": m.gSpeed / 1e3,
        "head_mot_deg": m.headMot,
        "s_acc_mps": m.sAcc / 1e3,
        "head_acc_deg": m.headAcc,
        "p_dop": m.pDOP,
        "valid_date_time()": bool(m.validDate and m.validTime),
        "fully_resolved()": bool(m.fullyResolved),
        "gnss_fix_ok()": bool(m.gnssFixOk),
        "diff_soln()": bool(m.diffSoln),
        "carr_soln()": m.carrSoln,
    }
    if hasattr(m, "flags3"):  # 92-byte layout (u-blox 8 and later)
        f.update(
            {
                "flags3": le(m.flags3),
                "invalid_llh()": bool(m.invalidLlh),
                "head_veh_deg": m.headVeh,
                "mag_dec_deg": m.magDec,
                "mag_acc_deg": m.magAcc,
            }
        )
    return f


def nav_sol(m):
    return {
        "itow_ms": m.iTOW,
        "ftow_ns": m.fTOW,
        "week": m.week,
        "gps_fix": m.gpsFix,
        "flags": le(m.flags),
        "ecef_x_m": m.ecefX / 1e2,
        "ecef_y_m": m.ecefY / 1e2,
        "ecef_z_m": m.ecefZ / 1e2,
        "p_acc_m": m.pAcc / 1e2,
        "ecef_vx_mps": m.ecefVX / 1e2,
        "ecef_vy_mps": m.ecefVY / 1e2,
        "ecef_vz_mps": m.ecefVZ / 1e2,
        "s_acc_mps": m.sAcc / 1e2,
        "p_dop": m.pDOP,
        "num_sv": m.numSV,
        "fix_ok()": bool(m.gpsfixOK),
        "diff_soln()": bool(m.diffSoln),
        "time_valid()": bool(m.wknSet and m.towSet),
    }


def nav_timegps(m):
    return {
        "itow_ms": m.iTOW,
        "ftow_ns": m.fTOW,
        "week": m.week,
        "leap_s": m.leapS,
        "valid": le(m.valid),
        "t_acc_ns": m.tAcc,
        "time_valid()": bool(m.towValid and m.weekValid),
        "leap_valid()": bool(m.leapSValid),
    }


def nav_posllh(m):
    return {
        "itow_ms": m.iTOW,
        "lon_deg": m.lon,
        "lat_deg": m.lat,
        "height_m": m.height / 1e3,
        "h_msl_m": m.hMSL / 1e3,
        "h_acc_m": m.hAcc / 1e3,
        "v_acc_m": m.vAcc / 1e3,
    }


def nav_velned(m):
    return {
        "itow_ms": m.iTOW,
        "vel_n_mps": m.velN / 1e2,
        "vel_e_mps": m.velE / 1e2,
        "vel_d_mps": m.velD / 1e2,
        "speed_mps": m.speed / 1e2,
        "g_speed_mps": m.gSpeed / 1e2,
        "heading_deg": m.heading,
        "s_acc_mps": m.sAcc / 1e2,
        "c_acc_deg": m.cAcc,
    }


def nav_dop(m):
    return {
        "itow_ms": m.iTOW,
        "g_dop": m.gDOP,
        "p_dop": m.pDOP,
        "t_dop": m.tDOP,
        "v_dop": m.vDOP,
        "h_dop": m.hDOP,
        "n_dop": m.nDOP,
        "e_dop": m.eDOP,
    }


def nav_status(m):
    return {
        "itow_ms": m.iTOW,
        "gps_fix": m.gpsFix,
        "flags": le(m.flags),
        "fix_stat": le(m.fixStat),
        "flags2": le(m.flags2),
        "ttff_ms": m.ttff,
        "msss_ms": m.msss,
        "fix_ok()": bool(m.gpsFixOk),
        "diff_soln()": bool(m.diffSoln),
        "carr_soln()": m.carrSoln,
    }


def nav_timeutc(m):
    return {
        "itow_ms": m.iTOW,
        "t_acc_ns": m.tAcc,
        "nano_ns": m.nano,
        "year": m.year,
        "month": m.month,
        "day": m.day,
        "hour": m.hour,
        "min": m.min,
        "sec": m.sec,
        "valid": le(m.validflags),
        "utc_valid()": bool(m.validUTC),
    }


def nav_sat(m):
    f = {"itow_ms": m.iTOW, "num_svs": m.numSvs}
    for i in range(1, m.numSvs + 1):
        s = f"sats[{i - 1}]."
        f.update(
            {
                s + "gnss_id": g(m, "gnssId", i),
                s + "sv_id": g(m, "svId", i),
                s + "cno_dbhz": g(m, "cno", i),
                s + "elev_deg": g(m, "elev", i),
                s + "azim_deg": g(m, "azim", i),
                s + "pr_res_m": g(m, "prRes", i),
                s + "used": bool(g(m, "svUsed", i)),
                s + "quality": g(m, "qualityInd", i),
                s + "health": g(m, "health", i),
                s + "flags": le(g(m, "flags", i)),
            }
        )
    return f


def nav_svinfo(m):
    f = {"itow_ms": m.iTOW, "num_ch": m.numCh, "global_flags": le(m.globalFlags)}
    k = 0
    unknown = 0
    for i in range(1, m.numCh + 1):
        sv = legacy_sv(g(m, "svid", i))  # conv: legacy numbering, see the module doc
        if sv is None:
            unknown += 1
            continue
        s = f"sats[{k}]."
        k += 1
        f.update(
            {
                s + "chn": g(m, "chn", i),
                s + "gnss_id": sv[0],
                s + "sv_id": sv[1],
                s + "cno_dbhz": g(m, "cno", i),
                s + "elev_deg": g(m, "elev", i),
                s + "azim_deg": g(m, "azim", i),
                s + "pr_res_m": g(m, "prRes", i) / 1e2,
                s + "used": bool(g(m, "svUsed", i)),
                s + "quality": g(m, "qualityInd", i),
                # navsync's SatInfo.health: 1 healthy, 2 unhealthy
                s + "health": 2 if g(m, "unhealthy", i) else 1,
                s + "flags": le(g(m, "flags", i)),
            }
        )
    f["unknown"] = unknown
    return f


def nav_eoe(m):
    return {"itow_ms": m.iTOW}


def tim_tp(m):
    # pyubx2 scales towSubMS by 2^-32 (ms) and rounds to 1e-12 ms: back in navsync's unit
    # (2^-32 ms) that is within 0.003 of the integer sent.
    sub = m.towSubMS * 2.0**32
    return {
        "tow_ms": m.towMS,
        "tow_sub_ms": sub,
        "q_err_ps": m.qErr,
        "week": m.week,
        "flags": le(m.flags),
        "ref_info": le(m.refinfo),
        "utc_time_base()": bool(m.timeBase),
        "q_err_valid()": not m.qErrInvalid,
        # time of week of the pulse, ns, the sub-millisecond part rounded half up
        "tow_ns()": m.towMS * 1_000_000 + math.floor(round(sub) * 1e6 / 2.0**32 + 0.5),
    }


def tim_tm2(m):
    return {
        "ch": m.ch,
        "flags": le(m.flags),
        "count": m.count,
        "week_rising": m.wnR,
        "week_falling": m.wnF,
        "tow_rising_ms": m.towMsR,
        "tow_sub_rising_ns": m.towSubMsR,
        "tow_falling_ms": m.towMsF,
        "tow_sub_falling_ns": m.towSubMsF,
        "acc_est_ns": m.accEst,
        "time_valid()": bool(m.time),
        "time_base()": m.timeBase,
    }


def rxm_rawx(m):
    f = {
        "rcv_tow_s": m.rcvTow,
        "week": m.week,
        "leap_s": m.leapS,
        "num_meas": m.numMeas,
        "rec_stat": le(m.recStat),
        "version": m.reserved1 & 0xFF,  # conv: first byte of pyubx2's U3 `reserved1`
    }
    for i in range(1, m.numMeas + 1):
        s = f"meas[{i - 1}]."
        f.update(
            {
                s + "pr_mes_m": g(m, "prMes", i),
                s + "cp_mes_cycles": g(m, "cpMes", i),
                s + "do_mes_hz": g(m, "doMes", i),
                s + "gnss_id": g(m, "gnssId", i),
                s + "sv_id": g(m, "svId", i),
                s + "sig_id": g(m, "sigId", i),
                s + "freq_id": g(m, "freqId", i),
                s + "locktime_ms": g(m, "locktime", i),
                s + "cno_dbhz": g(m, "cno", i),
                # conv: the protocol's scalings of the 4-bit indices pyubx2 gives
                s + "pr_stdev_m": 0.01 * 2 ** g(m, "prStd", i),
                s + "cp_stdev_cycles": 0.004 * g(m, "cpStd", i),
                s + "do_stdev_hz": 0.002 * 2 ** g(m, "doStd", i),
                s + "trk_stat": le(g(m, "trkStat", i)),
            }
        )
    return f


def rxm_sfrbx(m):
    f = {
        "gnss_id": m.gnssId,
        "sv_id": m.svId,
        "sig_id": m.sigId,
        "freq_id": m.freqId,
        "num_words": m.numWords,
        "chn": m.chn,
        "version": m.version,
    }
    for i in range(1, m.numWords + 1):
        f[f"words[{i - 1}]"] = g(m, "dwrd", i)
    return f


def esf_meas(m):
    f = {"time_tag_ms": m.timeTag, "flags": le(m.flags), "id": m.id}
    for i in range(1, m.numMeas + 1):
        f[f"readings[{i - 1}].data_type"] = g(m, "dataType", i)
        f[f"readings[{i - 1}].value"] = g(m, "dataField", i)
    # conv: pyubx2 reads every 4 bytes after the header as a data block, so the calibrated
    # time tag (present when calibTtagValid) is block numMeas + 1.
    f["calib_ttag_ms"] = le(g(m, "data", m.numMeas + 1)) if m.calibTtagValid else None
    return f


def esf_raw(m):
    f = {}
    i = 1
    while hasattr(m, f"data_{i:02d}"):
        w = le(g(m, "data", i))  # conv: raw X4 word: bits 0-23 data, 24-29 type
        s = f"readings[{i - 1}]."
        f[s + "data_type"] = (w >> 24) & 0x3F
        f[s + "value"] = w & 0xFFFFFF
        f[s + "s_ttag"] = le(g(m, "sTag", i))
        i += 1
    return f


def hnr_pvt(m):
    return {
        "itow_ms": m.iTOW,
        "year": m.year,
        "month": m.month,
        "day": m.day,
        "hour": m.hour,
        "min": m.min,
        "sec": m.second,
        "valid": le(m.valid),
        "nano_ns": m.nano,
        "gps_fix": m.gpsFix,
        "flags": le(m.flags),
        "lon_deg": m.lon,
        "lat_deg": m.lat,
        "height_m": m.height / 1e3,
        "h_msl_m": m.hMSL / 1e3,
        "g_speed_mps": m.gSpeed / 1e3,
        "speed_mps": m.speed / 1e3,
        "head_mot_deg": m.headMot,
        "head_veh_deg": m.headVeh,
        "h_acc_m": m.hAcc / 1e3,
        "v_acc_m": m.vAcc / 1e3,
        "s_acc_mps": m.sAcc / 1e3,
        "head_acc_deg": m.headAcc,
        "valid_date_time()": bool(m.validDate and m.validTime),
        "fix_ok()": bool(m.GPSfixOK),
        "diff_soln()": bool(m.DiffSoln),
    }


def mon_ver(m):
    f = {"sw_version": text(m.swVersion), "hw_version": text(m.hwVersion)}
    i = 1
    while hasattr(m, f"extension_{i:02d}"):
        f[f"extensions[{i - 1}]"] = text(g(m, "extension", i))
        i += 1
    return f


def ack(m):
    return {"cls_id": m.clsID, "msg_id": m.msgID}


FIELDS = {
    "NAV-PVT": nav_pvt,
    "NAV-SOL": nav_sol,
    "NAV-TIMEGPS": nav_timegps,
    "NAV-POSLLH": nav_posllh,
    "NAV-VELNED": nav_velned,
    "NAV-DOP": nav_dop,
    "NAV-STATUS": nav_status,
    "NAV-TIMEUTC": nav_timeutc,
    "NAV-SAT": nav_sat,
    "NAV-SVINFO": nav_svinfo,
    "NAV-EOE": nav_eoe,
    "TIM-TP": tim_tp,
    "TIM-TM2": tim_tm2,
    "RXM-RAWX": rxm_rawx,
    "RXM-SFRBX": rxm_sfrbx,
    "ESF-MEAS": esf_meas,
    "ESF-RAW": esf_raw,
    "HNR-PVT": hnr_pvt,
    "MON-VER": mon_ver,
    "ACK-ACK": ack,
    "ACK-NAK": ack,
}


def receiver_bytes(path):
    """The capture without gpsd's leading `#` comment lines."""
    with open(path, "rb") as fh:
        data = fh.read()
    while data.startswith(b"#"):
        nl = data.find(b"\n")
        data = data[nl + 1 :] if nl >= 0 else b""
    return data


def dump(path, out):
    name = os.path.basename(path)
    stream = io.BytesIO(receiver_bytes(path))
    # parsing=PARSE_NONE: the reader only frames (and so never drops a frame it cannot
    # parse); each frame is then parsed below, where a failure can be reported.
    reader = UBXReader(stream, protfilter=UBX_PROTOCOL, quitonerror=ERR_IGNORE, parsing=PARSE_NONE)
    index = 0
    for raw, _ in reader:
        rec = {
            "capture": name,
            "offset": stream.tell() - len(raw),
            "class": raw[2],
            "id": raw[3],
            "length": len(raw) - 8,
            "checksum_ok": calc_checksum(raw[2:-2]) == raw[-2:],
        }
        if rec["checksum_ok"]:
            rec["index"] = index
            index += 1
            try:
                msg = UBXReader.parse(raw, validate=VALCKSUM, msgmode=GET, parsebitfield=2)
                rec["identity"] = msg.identity
                conv = FIELDS.get(msg.identity)
                if conv is not None:
                    rec["fields"] = conv(msg)
            except Exception as err:  # pyubx2 rejects the payload: reported, not fatal
                rec["error"] = f"{type(err).__name__}: {err}"
        out.write(json.dumps(rec) + "\n")


def main():
    if len(sys.argv) < 2:
        sys.exit("usage: ubx_pyubx2_dump.py CAPTURE...")
    for path in sys.argv[1:]:
        dump(path, sys.stdout)


if __name__ == "__main__":
    main()
