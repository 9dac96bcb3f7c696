"""A micros_rt node serving or calling sensor_msgs/SetCameraInfo over MQTT (micros_rt.bridges.mqtt.services).

Run with the project's venv and MICROS_RT_QOS_PROFILE naming a profile with an 'mqtt' section. JSON lines:
  serve: {"event": "ready"} once served over the broker; {"event": "served", "frame_id"} per request
  call:  {"event": "reply", "frame_id", "status"} per call (--threads calls at once); {"event": "error",
         "text", "seconds"} for a call that raised; {"event": "done"}
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
import time
from typing import Any

import rospy
from sensor_msgs.srv import SetCameraInfo, SetCameraInfoRequest, SetCameraInfoResponse

import micros_rt
from micros_rt.bridges.mqtt.services import Service, ServiceProxy

_print_lock = threading.Lock()


def emit(event: str, **fields: Any) -> None:
    with _print_lock:
        sys.stdout.write(json.dumps({"event": event, **fields}) + "\n")
        sys.stdout.flush()


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("mode", choices=["serve", "call"])
    ap.add_argument("--service", default="/camera/set_camera_info")
    ap.add_argument("--id", default="1", help="serve: this server's name in its answers")
    ap.add_argument("--count", type=int, default=20, help="call: how many calls")
    ap.add_argument("--threads", type=int, default=4, help="call: calls in flight at once")
    ap.add_argument("--timeout", type=float, default=5.0)
    ap.add_argument("--duration", type=float, default=60.0)
    args = ap.parse_args()
    micros_rt.init_node(f"mqtt_srv_{args.mode}_{args.id}", disable_signals=False)

    if args.mode == "serve":
        def handler(req: Any) -> Any:
            frame = req.camera_info.header.frame_id
            emit("served", frame_id=frame)
            if frame == "fail":
                raise ValueError("this server refuses frame 'fail'")
            return SetCameraInfoResponse(success=True, status_message=f"server {args.id} got {frame}")

        service = Service(args.service, SetCameraInfo, handler)
        if not service._conn.wait_connected(20):
            emit("error", text="no broker")
            return 1
        time.sleep(0.3)      # the shared subscription has reached the broker
        emit("ready")
        end = time.monotonic() + args.duration
        while time.monotonic() < end and not rospy.is_shutdown():
            time.sleep(0.1)
        service.close()
        return 0

    proxy = ServiceProxy(args.service, SetCameraInfo, timeout=args.timeout)
    if not proxy._conn.wait_connected(20):
        emit("error", text="no broker")
        return 1
    time.sleep(0.3)

    def call(i: int) -> None:
        req = SetCameraInfoRequest()
        req.camera_info.header.frame_id = f"call {i}"
        t0 = time.monotonic()
        try:
            rsp = proxy(req)
            emit("reply", i=i, frame_id=f"call {i}", status=rsp.status_message)
        except rospy.ServiceException as exc:
            emit("error", i=i, text=str(exc), seconds=time.monotonic() - t0)

    ids = iter(range(args.count))
    lock = threading.Lock()

    def worker() -> None:
        while True:
            with lock:
                i = next(ids, None)
            if i is None:
                return
            call(i)

    threads = [threading.Thread(target=worker) for _ in range(args.threads)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    emit("done")
    micros_rt.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
