"""``depthbench capture devices``: list connected RealSense and OAK devices."""
from __future__ import annotations

import json

#: Drivers that talk to hardware (replay and azure_kinect play files and have nothing to list).
LIVE_DRIVERS = ("realsense", "oakd")


def add_parser(sub) -> None:
    p = sub.add_parser("devices", help="list connected RealSense and OAK-D cameras",
                       description="Ask each SDK (pyrealsense2, depthai) which cameras are connected and print one "
                                   "line per device: driver, serial (the value a rig file's 'serial' needs), model, "
                                   "firmware. Exits 0 also when none is found.",
                       epilog="Azure Kinect recordings are imported ('depthbench capture import azure-kinect'), "
                              "not listed here.")
    p.add_argument("--driver", action="append", choices=LIVE_DRIVERS,
                   help="ask only this driver (repeatable; default all)")
    p.add_argument("--json", action="store_true", help="print a JSON list instead of text")
    p.set_defaults(func=run)


def list_devices(drivers: tuple[str, ...] | list[str] | None = None) -> list:
    """:class:`~capture.drivers.base.DriverListing` per driver (devices, or what went wrong)."""
    from capture.drivers.base import enumerate_devices

    return enumerate_devices(list(drivers or LIVE_DRIVERS))


def run(args) -> int:
    listings = list_devices(args.driver)
    if args.json:
        rows = [{"driver": li.driver, "problem": li.problem,
                 "devices": [{"serial": d.serial, "model": d.model, "firmware": d.firmware, **dict(d.details)}
                             for d in li.devices]} for li in listings]
        print(json.dumps(rows, indent=2))
        return 0
    total = 0
    for li in listings:
        if li.problem:
            print(f"{li.driver:<10} unavailable: {li.problem}")
            continue
        if not li.devices:
            print(f"{li.driver:<10} no devices found")
        for d in li.devices:
            total += 1
            fw = f"  firmware {d.firmware}" if d.firmware else ""
            extra = "  " + " ".join(f"{k}={v}" for k, v in d.details.items()) if d.details else ""
            print(f"{li.driver:<10} {d.serial:<24} {d.model}{fw}{extra}")
    names = " or ".join("RealSense" if li.driver == "realsense" else "OAK" for li in listings)
    print(f"{total} device(s) connected" if total else f"No {names} device found.")
    return 0
