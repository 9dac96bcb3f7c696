"""An unmodified rospy script with a service or a service proxy: nothing of micros_rt in it.

    plain_service.py serve NAME [--duration S]     rospy.Service(NAME, std_srvs/SetBool): answers
                                                   success=data, message "plain NAME got <data>"
    plain_service.py call NAME [--count N]         rospy.wait_for_service(NAME, 30), rospy.ServiceProxy(NAME,
                                                   SetBool), then N calls alternating True/False

Prints one JSON line per event (ready, response, error, done). Run as a stock node with /usr/bin/python3, or
under ``micros-rt run`` (tests/integration/test_cli_run.py), where the same lines reach ROS 2 too.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Any

import rospy
from std_srvs.srv import SetBool, SetBoolResponse


def emit(event: str, **fields: Any) -> None:
    sys.stdout.write(json.dumps({"event": event, **fields}) + "\n")
    sys.stdout.flush()


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("mode", choices=("serve", "call"))
    ap.add_argument("name")
    ap.add_argument("--count", type=int, default=3)
    ap.add_argument("--duration", type=float, default=60.0)
    args = ap.parse_args(rospy.myargv()[1:])
    rospy.init_node("plain_service", disable_rosout=True)
    if args.mode == "serve":
        server = rospy.Service(args.name, SetBool,
                               lambda req: SetBoolResponse(success=req.data, message=f"plain {args.name} got {req.data}"))
        emit("ready", classes=[type(server).__module__])
        end = time.monotonic() + args.duration
        while not rospy.is_shutdown() and time.monotonic() < end:
            time.sleep(0.1)
        server.shutdown("done")
        return 0
    rospy.wait_for_service(args.name, 30.0)   # the usual pattern: the function, then the proxy
    proxy = rospy.ServiceProxy(args.name, SetBool)
    proxy.wait_for_service(30.0)
    for i in range(args.count):
        try:
            answer = proxy(i % 2 == 0)
            emit("response", success=answer.success, message=answer.message)
        except rospy.ServiceException as exc:
            emit("error", message=str(exc))
    emit("done", classes=[type(proxy).__module__])
    return 0


if __name__ == "__main__":
    sys.exit(main())
