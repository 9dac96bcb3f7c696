"""A stock rospy node (no micros_rt) serving std_srvs/SetBool, for the board to call through mcu-bridge.

Run with /usr/bin/python3. Prints {"event": "ready"} once the service is registered, then
{"event": "called", "data": ...} for every call; answers success=True, message="mode on"/"mode off".
Exits after --duration seconds, or promptly on SIGINT/SIGTERM.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from typing import Any

import rospy
from std_srvs.srv import SetBool, SetBoolResponse


def emit(event: str, **fields: Any) -> None:
    fields["event"] = event
    sys.stdout.write(json.dumps(fields) + "\n")
    sys.stdout.flush()


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--service", default="/set_mode")
    ap.add_argument("--duration", type=float, default=60.0)
    args = ap.parse_args()
    rospy.init_node(f"mcu_ros_service_{os.getpid()}", disable_rosout=True)

    def handle(req: Any) -> SetBoolResponse:
        emit("called", data=bool(req.data))
        return SetBoolResponse(success=True, message="mode on" if req.data else "mode off")

    rospy.Service(args.service, SetBool, handle)
    emit("ready", service=args.service)
    # Not rospy.sleep: on the wall clock it is time.sleep, which rospy's SIGINT/SIGTERM handler does not cut
    # short (it only flags shutdown), so the harness's stop waited for SIGKILL (10 s).
    end = time.monotonic() + args.duration
    while not rospy.is_shutdown() and time.monotonic() < end:
        time.sleep(0.1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
