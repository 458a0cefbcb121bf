#!/usr/bin/env python3
"""Writes UBX frames built by pyubx2 for the message types the gpsd corpus lacks (NAV-VELNED,
TIM-TM2, RXM-RAWX), so that navsync's decoders of them are cross-checked against pyubx2 like
the others (tests/tests/drivers/ubx_pyubx2.rs). Usage: ubx_pyubx2_build.py OUT.ubx

The values are drawn from a seeded generator over each field's whole range (the extremes
included), pyubx2 serialises them from the interface description, and the file goes through
the same dump and comparison as the real captures.
"""

import random
import sys

from pyubx2 import GET, UBXMessage

rng = random.Random(20261201)


def nav_velned(i):
    return UBXMessage(
        "NAV",
        "NAV-VELNED",
        GET,
        iTOW=rng.randrange(0, 604800000),
        velN=rng.randrange(-(2**31), 2**31),
        velE=rng.randrange(-50000, 50000),
        velD=-(2**31) if i == 0 else rng.randrange(-5000, 5000),
        speed=rng.randrange(0, 2**32),
        gSpeed=rng.randrange(0, 60000),
        heading=rng.randrange(-18000000, 36000000) * 1e-5,
        sAcc=rng.randrange(0, 2**32),
        cAcc=rng.randrange(0, 18000000) * 1e-5,
    )


def tim_tm2(i):
    return UBXMessage(
        "TIM",
        "TIM-TM2",
        GET,
        ch=i % 2,
        mode=rng.randrange(2),
        run=rng.randrange(2),
        newFallingEdge=rng.randrange(2),
        timeBase=rng.randrange(3),
        utc=rng.randrange(2),
        time=rng.randrange(2),
        newRisingEdge=rng.randrange(2),
        count=rng.randrange(0, 2**16),
        wnR=rng.randrange(0, 2**16),
        wnF=rng.randrange(0, 2**16),
        towMsR=rng.randrange(0, 604800000),
        towSubMsR=rng.randrange(0, 1000000),
        towMsF=rng.randrange(0, 604800000),
        towSubMsF=rng.randrange(0, 2**32) if i == 3 else rng.randrange(0, 1000000),
        accEst=rng.randrange(0, 2**32),
    )


def rxm_rawx(i):
    n = [0, 1, 17, 32][i % 4]
    fields = dict(
        rcvTow=rng.uniform(0, 604800),
        week=rng.randrange(0, 2**16),
        leapS=rng.randrange(-128, 128),
        numMeas=n,
        leapSec=rng.randrange(2),
        clkReset=rng.randrange(2),
        reserved1=1,  # the version byte (then two reserved bytes)
    )
    for k in range(1, n + 1):
        s = f"_{k:02d}"
        fields.update(
            {
                "prMes" + s: rng.uniform(1.9e7, 2.6e7),
                "cpMes" + s: rng.uniform(-1e9, 1e9),
                "doMes" + s: rng.uniform(-5000, 5000),
                "gnssId" + s: rng.choice([0, 1, 2, 3, 5, 6]),
                "svId" + s: rng.randrange(1, 256),
                "sigId" + s: rng.randrange(0, 8),
                "freqId" + s: rng.randrange(0, 14),
                "locktime" + s: rng.randrange(0, 2**16),
                "cno" + s: rng.randrange(0, 256),
                "prStd" + s: rng.randrange(16),
                "cpStd" + s: rng.randrange(16),
                "doStd" + s: rng.randrange(16),
                "prValid" + s: rng.randrange(2),
                "cpValid" + s: rng.randrange(2),
                "halfCyc" + s: rng.randrange(2),
                "subHalfCyc" + s: rng.randrange(2),
            }
        )
    return UBXMessage("RXM", "RXM-RAWX", GET, **fields)


def main():
    if len(sys.argv) != 2:
        sys.exit("usage: ubx_pyubx2_build.py OUT.ubx")
    with open(sys.argv[1], "wb") as out:
        for i in range(8):
            for build in (nav_velned, tim_tm2, rxm_rawx):
                out.write(build(i).serialize())


if __name__ == "__main__":
    main()
