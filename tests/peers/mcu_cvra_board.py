"""A board that speaks exactly the bytes CVRA's code wrote (tests/fixtures/cvra/), for mcu-bridge tests.

No CVRA code and no micros_rt: it replays the captured bytes and reports what reaches it.

- ``--stream HEX`` (repeatable): datagrams sent to the bridge's topic port, in turn, at ``--rate`` Hz,
  ``--count`` in all (``{"event": "sent"}`` at the end);
- ``--answer NAME=HEX`` / ``--answer NAME=close`` (repeatable): its service port answers a call of NAME with
  those bytes (unframed, as CVRA's servers do) or closes the connection without answering; every request is
  printed ``{"event": "served", "name", "rest", "hex"}``, ``rest`` what follows the name (two objects: the
  second object; one array: its tail);
- ``--call HEX`` (repeatable): after ``--call-after`` s, framed requests sent to the bridge's service port one
  connection each; ``{"event": "call_result", "request": HEX, "answer": HEX, "decoded": ...}``;
- datagrams that reach its topic port are printed ``{"event": "recv", "hex", "decoded"}``;
- ``--era final|mid2015|readme``: its service port reads a request as that era's ``cvra_rpc`` server does
  (``handle_connection``; the fixtures in tests/fixtures/cvra/ show each): ``args`` in the ``served`` event is
  what the era's handler is given, and a request that era's code cannot unpack is closed unanswered, as the
  server's exception does (0670b782's ``name, params = decode_call(...)`` raises ValueError on one object).

Run with the project's venv python (msgpack). Ports and addresses as the C stand-in's options.
"""

from __future__ import annotations

import argparse
import json
import select
import socket
import sys
import time
from typing import Any, Dict, List, Optional, Tuple

import msgpack


def emit(event: str, **fields: Any) -> None:
    fields["event"] = event
    sys.stdout.write(json.dumps(fields, default=lambda b: {"bin": list(b)}) + "\n")
    sys.stdout.flush()


def objects(data: bytes) -> List[Any]:
    unpacker = msgpack.Unpacker(raw=False, strict_map_key=False)
    unpacker.feed(data)
    return list(unpacker)


def unframe(frame: bytes) -> bytes:
    """The payload of a serial datagram (frame without its END): SLIP unescaped, CRC32 removed (not checked)."""
    return frame.replace(b"\xdb\xdc", b"\xc0").replace(b"\xdb\xdd", b"\xdb")[:-4]


def name_and_rest(payload: bytes) -> Tuple[Optional[str], Any]:
    try:
        objs = objects(payload)
    except Exception as exc:  # report, never crash: a board prints what it could not read
        return None, f"not MessagePack: {exc}"
    if len(objs) == 2 and isinstance(objs[0], str):
        return objs[0], objs[1]
    if len(objs) == 1 and isinstance(objs[0], list) and objs[0] and isinstance(objs[0][0], str):
        return objs[0][0], objs[0][1:]
    return None, objs


def era_args(era: str, payload: bytes) -> Tuple[Optional[str], Any]:
    """(name, what the era's handler gets) of a request, or (None, why) when that era's code raises."""
    try:
        objs = objects(payload)
    except Exception as exc:
        return None, f"not MessagePack: {exc}"
    if era == "readme":                       # 0670b782: name, params = the unpacker's objects
        if len(objs) != 2:
            return None, f"ValueError: not enough values to unpack (expected 2, got {len(objs)})"
        return objs[0], objs[1]
    if len(objs) != 1 or not isinstance(objs[0], list) or not objs[0]:
        return None, "not an array [name, ...]"
    if era == "mid2015":                      # feb95469: the handler gets the array's tail
        return objs[0][0], objs[0][1:]
    if len(objs[0]) != 2:                     # babf2cfa: name, args = the array
        return None, f"ValueError: too many values to unpack (expected 2, got {len(objs[0])})"
    return objs[0][0], objs[0][1]


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--address", default="127.0.0.2")
    ap.add_argument("--topic-port", type=int, default=20000)
    ap.add_argument("--service-port", type=int, default=20001)
    ap.add_argument("--bridge", default="127.0.0.1")
    ap.add_argument("--bridge-topic-port", type=int, default=20000)
    ap.add_argument("--bridge-service-port", type=int, default=20001)
    ap.add_argument("--stream", action="append", default=[])
    ap.add_argument("--rate", type=float, default=20.0)
    ap.add_argument("--count", type=int, default=0)
    ap.add_argument("--answer", action="append", default=[])
    ap.add_argument("--call", action="append", default=[])
    ap.add_argument("--call-after", type=float, default=0.5)
    ap.add_argument("--duration", type=float, default=60.0)
    ap.add_argument("--era", choices=("final", "mid2015", "readme"), default=None)
    args = ap.parse_args()

    answers: Dict[str, Optional[bytes]] = {}
    for item in args.answer:
        name, _, value = item.partition("=")
        answers[name] = None if value == "close" else bytes.fromhex(value)
    udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    udp.bind((args.address, args.topic_port))
    tcp = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    tcp.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    tcp.bind((args.address, args.service_port))
    tcp.listen(8)
    emit("ready")
    streams = [bytes.fromhex(h) for h in args.stream]
    start = time.monotonic()
    next_send, sent, period = start, 0, 1.0 / args.rate if args.rate > 0 else 0.0
    calls = [bytes.fromhex(h) for h in args.call]
    call_at = start + args.call_after
    while time.monotonic() < start + args.duration:
        now = time.monotonic()
        if streams and sent < args.count and now >= next_send:
            udp.sendto(streams[sent % len(streams)], (args.bridge, args.bridge_topic_port))
            sent += 1
            next_send += period
            if sent == args.count:
                emit("sent", sent=sent)
            continue
        if calls and now >= call_at:
            for request in calls:
                call(args, request)
            calls = []
            continue
        ready, _, _ = select.select([udp, tcp], [], [], 0.02)
        if udp in ready:
            data, _ = udp.recvfrom(65536)
            try:
                decoded: Any = objects(data)
            except Exception as exc:
                decoded = f"not MessagePack: {exc}"
            emit("recv", hex=data.hex(), decoded=decoded)
        if tcp in ready:
            serve(tcp, answers, args.era)
    emit("done", sent=sent)
    return 0


def serve(tcp: socket.socket, answers: Dict[str, Optional[bytes]], era: Optional[str]) -> None:
    conn, _ = tcp.accept()
    with conn:
        conn.settimeout(5.0)
        data = b""
        try:
            while not data.endswith(b"\xc0"):
                chunk = conn.recv(4096)
                if not chunk:
                    break
                data += chunk
        except socket.timeout:
            pass
        name, rest = name_and_rest(unframe(data[:-1]))
        if era is None:
            emit("served", name=name, rest=rest, hex=data.hex())
        else:
            handled, handler_args = era_args(era, unframe(data[:-1]))
            emit("served", name=name, rest=rest, hex=data.hex(), era=era, handled=handled is not None,
                 args=handler_args)
            if handled is None:
                return                        # the era's server raised: the connection closes unanswered
        answer = answers.get(name or "")
        if answer is not None:
            conn.sendall(answer)


def call(args: argparse.Namespace, request: bytes) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind((args.address, 0))
        sock.settimeout(10.0)
        sock.connect((args.bridge, args.bridge_service_port))
        sock.sendall(request)
        answer = b""
        try:
            while True:
                chunk = sock.recv(4096)
                if not chunk:
                    break
                answer += chunk
        except socket.timeout:
            pass
    try:
        decoded: Any = objects(answer)
    except Exception as exc:
        decoded = f"not MessagePack: {exc}"
    emit("call_result", request=request.hex(), answer=answer.hex(), decoded=decoded)


if __name__ == "__main__":
    sys.exit(main())
