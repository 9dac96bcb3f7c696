"""A stock rospy service server or client of a type that exists in no package (built at run time with genpy,
as a node of a package the relays' hosts lack would have it compiled). Stock Python, no micros_rt.

    dyn_service.py server --name /add_two --seconds 120     # prints {"event": "ready"}, then one "served" per call
    dyn_service.py call --name /robot_a/add_two --a 2 --b 40   # prints {"event": "response", ...} or "error"
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Any

import genmsg  # type: ignore[import-untyped]
import genmsg.msg_loader  # type: ignore[import-untyped]
import genpy.dynamic
import rospy

TYPE = "mrt_runtime/AddTwo"
TEXT = "int64 a\nint64 b\n---\nint64 sum\nstring note\n"
#: --other-definition: the same type name, built from a definition that differs (another md5)
OTHER_TEXT = "int32 a\nint32 b\n---\nint64 sum\nstring note\n"


def emit(event: str, **fields: Any) -> None:
    # one write per line: a log line from another thread must not land inside it
    sys.stdout.write(json.dumps({"event": event, **fields}) + "\n")
    sys.stdout.flush()


def service_class(text: str) -> Any:
    context = genmsg.MsgContext.create_default()
    md5 = genmsg.compute_md5(context, genmsg.msg_loader.load_srv_from_string(context, text, TYPE))
    request_text, response_text = text.split("---\n")
    request = genpy.dynamic.generate_dynamic(TYPE + "Request", request_text)[TYPE + "Request"]
    response = genpy.dynamic.generate_dynamic(TYPE + "Response", response_text)[TYPE + "Response"]
    return type("AddTwo", (), {"_type": TYPE, "_md5sum": md5, "_request_class": request,
                               "_response_class": response})


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("mode", choices=["server", "call"])
    ap.add_argument("--name", default="/add_two")
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--a", type=int, default=1)
    ap.add_argument("--b", type=int, default=2)
    ap.add_argument("--other-definition", action="store_true")
    args = ap.parse_args()
    srv = service_class(OTHER_TEXT if args.other_definition else TEXT)
    if args.mode == "server":
        rospy.init_node("add_two_server")

        def handle(req: Any) -> Any:
            emit("served", a=req.a, b=req.b)
            return srv._response_class(sum=req.a + req.b, note=f"robot A added {req.a} and {req.b}")

        rospy.Service(args.name, srv, handle)
        emit("ready", md5=srv._md5sum)
        end = time.monotonic() + args.seconds
        while not rospy.is_shutdown() and time.monotonic() < end:
            time.sleep(0.1)
        return 0
    rospy.init_node("add_two_client", anonymous=True)
    try:
        rospy.wait_for_service(args.name, timeout=30)
        res = rospy.ServiceProxy(args.name, srv)(srv._request_class(a=args.a, b=args.b))
    except (rospy.ServiceException, rospy.ROSException) as exc:
        emit("error", text=str(exc))
        return 1
    emit("response", sum=res.sum, note=res.note)
    return 0


if __name__ == "__main__":
    sys.exit(main())
