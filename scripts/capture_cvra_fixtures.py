#!/usr/bin/env python3
"""Recapture tests/fixtures/cvra/*.json: the bytes CVRA's own Python cvra_rpc writes, in each of its three eras.

Usage::

    .venv/bin/python scripts/capture_cvra_fixtures.py PATH [--out tests/fixtures/cvra] [--check]

``PATH`` is a clone of https://github.com/cvra/robot-software (a work tree or a bare git directory); the
files are read from the named commits with ``git show``, whatever is checked out, written to a temporary
directory and imported from there. Nothing of CVRA's is copied into this repository: the fixtures hold only
the bytes their functions returned (hex) and what their decoders made of micros_rt's bytes.

For each era the script runs CVRA's own functions -- ``message.encode``, ``service_call.encode_call`` (with
the era's ``serial_datagram(s)`` module), ``service_call.handle_connection`` with a stand-in socket (what a
CVRA server sends back for a handler's return value), ``message.decode``/``service_call.decode_call`` on
micros_rt's bytes -- and records each call, its bytes and the commit and file of the code. ``--check``
compares with the files already there instead of writing them (exit 1 on a difference).

CVRA's code of 2015 used msgpack-python 0.4's ``encoding='ascii'`` and packed ``str`` as raw: the script
gives it a thin msgpack wrapper that maps ``encoding=`` to ``raw=False`` and packs with
``use_bin_type=False`` unless told otherwise (the same bytes for strings up to 31 bytes, all that is used).
"""

from __future__ import annotations

import argparse
import functools
import importlib.util
import json
import subprocess
import sys
import tempfile
import types
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Tuple

import msgpack

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

# era -> (commit, {module: (commit, path)}, serial module name)
ERAS: Dict[str, Tuple[str, Dict[str, Tuple[str, str]], str]] = {
    "readme": ("0670b7827f2ca9b66e7a6b0480fc5d9d7f95ec4d", {
        "service_call": ("0670b7827f2ca9b66e7a6b0480fc5d9d7f95ec4d", "python/service_call.py"),
        # 0670b782 imports serial_datagrams, not yet in the tree: the serial-datagram repository's version of
        # the same day (subtree-merged into robot-software later, so its history is there)
        "serial_datagrams": ("58fd6c66e71f6387f492b5b7206d619b1a49bdca", "python/serial_datagrams.py"),
    }, "serial_datagrams"),
    "mid2015": ("feb95469952c65b03ce662d6fbdf359b18b73c20", {
        "message": ("feb95469952c65b03ce662d6fbdf359b18b73c20", "python/cvra_rpc/message.py"),
        "service_call": ("feb95469952c65b03ce662d6fbdf359b18b73c20", "python/cvra_rpc/service_call.py"),
        # the serial_datagram module current on 2015-05-20 (renamed from serial_datagrams on 2015-03-17)
        "serial_datagram": ("6dea8d15a1aec80b24e46d9615f05f7b901323d4", "python/serial_datagram.py"),
    }, "serial_datagram"),
    "final": ("babf2cfaa42f481966c1ab61fd37f76514250e21", {
        "message": ("babf2cfaa42f481966c1ab61fd37f76514250e21", "lib/simplerpc/python/cvra_rpc/message.py"),
        "service_call": ("babf2cfaa42f481966c1ab61fd37f76514250e21",
                         "lib/simplerpc/python/cvra_rpc/service_call.py"),
        "serial_datagram": ("babf2cfaa42f481966c1ab61fd37f76514250e21",
                            "lib/serial-datagram/python/serial_datagram.py"),
    }, "serial_datagram"),
}


def git_dir(path: Path) -> Path:
    return path / ".git" if (path / ".git").exists() else path


def show(repo: Path, commit: str, path: str) -> str:
    cp = subprocess.run(["git", "--git-dir", str(git_dir(repo)), "show", f"{commit}:{path}"], capture_output=True,
                        text=True)
    if cp.returncode != 0:
        raise SystemExit(f"capture_cvra_fixtures: cannot read {path} at {commit[:8]} from {repo}: {cp.stderr.strip()}"
                         f" (is it a clone of cvra/robot-software with its full history?)")
    return cp.stdout


def msgpack_shim() -> types.ModuleType:
    """msgpack as CVRA's 2015 code expects it (encoding='ascii'; str packed as raw)."""
    shim = types.ModuleType("msgpack")
    shim.__dict__.update({k: getattr(msgpack, k) for k in dir(msgpack) if not k.startswith("__")})

    def _strip(kw: Dict[str, Any]) -> Dict[str, Any]:
        if "encoding" in kw:
            kw.pop("encoding")
            kw["raw"] = False
        return kw

    def packb(obj: Any, **kw: Any) -> bytes:
        kw.setdefault("use_bin_type", False)
        return msgpack.packb(obj, **kw)  # type: ignore[no-any-return]

    shim.packb = packb  # type: ignore[attr-defined]
    shim.Unpacker = lambda *a, **kw: msgpack.Unpacker(*a, **_strip(kw))  # type: ignore[attr-defined]
    shim.unpackb = lambda *a, **kw: msgpack.unpackb(*a, **_strip(kw))  # type: ignore[attr-defined]
    return shim


def load_era(repo: Path, era: str, tmp: Path) -> Dict[str, types.ModuleType]:
    """Import the era's modules from the named commits (written under ``tmp``), with the msgpack shim."""
    _, files, serial_name = ERAS[era]
    saved = {name: sys.modules.get(name) for name in ("msgpack", serial_name)}
    sys.modules["msgpack"] = msgpack_shim()
    modules: Dict[str, types.ModuleType] = {}
    try:
        order = [serial_name] + [m for m in files if m != serial_name]
        for name in order:
            commit, path = files[name]
            source = tmp / era / f"{name}.py"
            source.parent.mkdir(parents=True, exist_ok=True)
            source.write_text(show(repo, commit, path))
            spec = importlib.util.spec_from_file_location(f"cvra_{era}_{name}", source)
            assert spec is not None and spec.loader is not None
            module = importlib.util.module_from_spec(spec)
            if name == serial_name:
                sys.modules[serial_name] = module
            spec.loader.exec_module(module)
            modules[name] = module
    finally:
        for name, mod in saved.items():
            if mod is None:
                sys.modules.pop(name, None)
            else:
                sys.modules[name] = mod
    return modules


class FakeSocket:
    """What handle_connection talks to: recv gives the request frame, send/sendall are recorded."""

    def __init__(self, frame: bytes) -> None:
        self._frame = frame
        self.sent = b""

    def recv(self, n: int) -> bytes:
        data, self._frame = self._frame[:n], self._frame[n:]
        return data

    def send(self, data: bytes) -> int:
        self.sent += data
        return len(data)

    sendall = send


def answer_of(service_call: types.ModuleType, frame: bytes, name: str, retval: Any) -> bytes:
    """What CVRA's handle_connection sends back when the handler of ``name`` returns ``retval``."""
    sock = FakeSocket(frame)
    service_call.handle_connection({name: lambda params: retval}, sock)
    return sock.sent


def outcome(fn: Callable[[], Any]) -> Dict[str, Any]:
    """fn()'s result as JSON-able data, or the exception it raised."""
    try:
        value = fn()
    except Exception as exc:  # the point: what CVRA's code does with the input
        return {"raises": f"{type(exc).__name__}: {exc}"}
    return {"returns": value if not isinstance(value, tuple) else list(value)}


def capture(repo: Path, era: str, tmp: Path) -> Dict[str, Any]:
    from micros_rt.transports.mcu import wire

    commit, files, serial_name = ERAS[era]
    mods = load_era(repo, era, tmp)
    sc = mods["service_call"]
    entries: List[Dict[str, Any]] = []

    def where(module: str) -> str:
        c, path = files[module]
        return f"{path}@{c[:8]}"

    def add(key: str, call: str, data: bytes, module: str, **extra: Any) -> None:
        entries.append({"id": key, "call": call, "hex": data.hex(), "code": where(module), **extra})

    def decoded(key: str, what: str, data: bytes, module: str, fn: Callable[[], Any]) -> None:
        entries.append({"id": key, "decoder": what, "input_hex": data.hex(), "code": where(module), **outcome(fn)})

    ser = mods[serial_name]
    if era == "readme":
        # service_call.encode_call(name, params): msgpack(name) + msgpack(params), as a serial datagram
        set_mode = sc.encode_call("set_mode", {"data": True})
        add("call_set_mode_map", 'encode_call("set_mode", {"data": True})', set_mode, "service_call")
        reset = sc.encode_call("reset", {})
        add("call_reset_no_params", 'encode_call("reset", {})  # call(address, "reset")', reset, "service_call")
        add("answer_hello", 'handle_connection: handler returns "Hello, client" (their example server)',
            answer_of(sc, reset, "reset", "Hello, client"), "service_call")
        add("answer_none", "handle_connection: handler returns None", answer_of(sc, reset, "reset", None),
            "service_call")
        ours = wire.encode_request("set_mode", {"data": True}, form=wire.WireForm.README)
        decoded("decode_call_micros_rt_readme", "name, params = decode_call(micros_rt's readme-form request)", ours,
                "service_call", lambda: list(sc.decode_call(ours)))
        old = bytes.fromhex("92a87365745f6d6f6465c3b3779734c0")  # what micros_rt wrote as readme before issue 37
        decoded("handle_connection_micros_rt_before", "handle_connection(micros_rt's readme request before issue 37)",
                old, "service_call", lambda: answer_of(sc, old, "set_mode", True).hex())
    else:
        msg = mods["message"]
        args_list: Any = [1.5, 2.5, 0.5]
        add("topic_odometry_raw", 'message.encode("odometry_raw", [1.5, 2.5, 0.5])',
            msg.encode("odometry_raw", args_list), "message")
        add("topic_no_args", 'message.encode("foo")', msg.encode("foo"), "message")
        if era == "final":
            add("topic_speed_bare", 'message.encode("speed", 1.5)  # like the firmware\'s stream_float',
                msg.encode("speed", 1.5), "message")
            add("topic_chatter_map", 'message.encode("chatter", {"data": "hi"})',
                msg.encode("chatter", {"data": "hi"}), "message")
            ping = sc.encode_call("ping", None)
            add("call_ping_nil", 'service_call.encode_call("ping", None)  # call(address, "ping")', ping,
                "service_call")
            add("call_set_mode_bare", 'service_call.encode_call("set_mode", True)',
                sc.encode_call("set_mode", True), "service_call")
            add("call_set_mode_list", 'service_call.encode_call("set_mode", [True])',
                sc.encode_call("set_mode", [True]), "service_call")
            add("call_lvl_list", 'service_call.encode_call("lvl", ["ros", "debug"])',
                sc.encode_call("lvl", ["ros", "debug"]), "service_call")
            add("answer_list", "handle_connection: handler returns [True, \"ok\"]",
                answer_of(sc, ping, "ping", [True, "ok"]), "service_call")
            # The C server (lib/simplerpc/service_call.c, service_call_process) is not run: it answers nil when the
            # handler wrote nothing; checked in the source, recorded as the one byte that cmp_write_nil writes.
            c_source = show(repo, commit, "lib/simplerpc/service_call.c")
            if "cmp_write_nil(&out_cmp)" not in c_source:
                raise SystemExit("capture_cvra_fixtures: service_call.c no longer writes nil for an empty answer")
            entries.append({"id": "c_answer_nil", "call": "service_call_process: the handler wrote nothing "
                            "(or no handler has the name) -> cmp_write_nil", "hex": "c0",
                            "code": f"lib/simplerpc/service_call.c@{commit[:8]}", "how": "read in the C source, "
                            "not run: MessagePack nil is the byte c0"})
        else:
            ping = sc.encode_call("ping", [])
            add("call_ping_no_params", 'service_call.encode_call("ping", [])  # call(address, "ping")', ping,
                "service_call")
            add("call_set_mode", 'service_call.encode_call("set_mode", [True])', sc.encode_call("set_mode", [True]),
                "service_call")
        add("answer_pong", 'handle_connection: handler returns "pong"', answer_of(sc, ping, "ping", "pong"),
            "service_call")
        add("answer_true", "handle_connection: handler returns True", answer_of(sc, ping, "ping", True),
            "service_call")
        add("answer_none", "handle_connection: handler returns None", answer_of(sc, ping, "ping", None),
            "service_call")
        form = wire.WireForm.FINAL if era == "final" else wire.WireForm.MID2015
        pose = {"x": wire.Float32(1.5), "y": wire.Float32(2.5), "theta": wire.Float32(0.5)}
        dgram = wire.encode_datagram("odometry_raw", pose, form=form)
        decoded("decode_micros_rt_pose2d", f"message.decode(micros_rt's {form.value} Pose2D datagram)", dgram,
                "message", lambda: list(msg.decode(dgram)))
        req = wire.encode_request("set_mode", {"data": True}, form=form)
        decoded("decode_call_micros_rt_set_mode", f"decode_call(micros_rt's {form.value} SetBool request)", req,
                "service_call", lambda: list(sc.decode_call(req)))
        empty = wire.encode_request("reset", {}, form=form)
        decoded("decode_call_micros_rt_empty", f"decode_call(micros_rt's {form.value} request of no fields)", empty,
                "service_call", lambda: list(sc.decode_call(empty)))
        old = wire.encode_request("set_mode", {"data": True}, form=wire.WireForm.MAP)
        decoded("decode_call_micros_rt_map", "decode_call(micros_rt's request before issue 37: [name, {fields}])",
                old, "service_call", lambda: list(sc.decode_call(old)))
    return {
        "repository": "https://github.com/cvra/robot-software",
        "era": era,
        "commit": commit,
        "files": {name: f"{path}@{c}" for name, (c, path) in files.items()},
        "captured_with": f"scripts/capture_cvra_fixtures.py, Python {sys.version.split()[0]}, msgpack "
                         f"{'.'.join(map(str, msgpack.version))} (wrapped as in the script's docstring)",
        "entries": entries,
    }


DEBRA_COMMIT = "947dc49"  # cvra/cvra_debra_ros master (2016-02-19); master_publisher.py last changed 2015-05-19


def capture_debra(debra: Path, repo: Path, tmp: Path) -> Dict[str, Any]:
    """CVRA's own bridge node (cvra_debra_ros master_bridge/scripts/master_publisher.py) fed micros_rt's final-form
    Pose2D datagram through the final cvra_rpc message.decode: the Pose2D it would publish (rospy stubbed)."""
    from micros_rt.transports.mcu import wire

    commit = subprocess.run(["git", "--git-dir", str(git_dir(debra)), "rev-parse", DEBRA_COMMIT],
                            capture_output=True, text=True, check=True).stdout.strip()
    path = "master_bridge/scripts/master_publisher.py"
    source = show(debra, commit, path)
    msg = load_era(repo, "final", tmp)["message"]
    published: List[Any] = []

    class Pose2D:
        x = y = theta = 0.0

    fake = {"rospy": types.ModuleType("rospy"), "cvra_msgs": types.ModuleType("cvra_msgs"),
            "cvra_msgs.msg": types.ModuleType("cvra_msgs.msg"), "cvra_rpc": types.ModuleType("cvra_rpc"),
            "cvra_rpc.message": msg}
    fake["cvra_msgs.msg"].Pose2D = Pose2D  # type: ignore[attr-defined]
    fake["cvra_msgs.msg"].JointInfo = object  # type: ignore[attr-defined]
    saved = {k: sys.modules.get(k) for k in fake}
    sys.modules.update(fake)
    try:
        namespace: Dict[str, Any] = {"__name__": "master_publisher"}
        exec(compile(source, path, "exec"), namespace)  # defines the callbacks; __main__ block not run
    finally:
        for k, mod in saved.items():
            if mod is None:
                sys.modules.pop(k, None)
            else:
                sys.modules[k] = mod
    namespace["pub_odometry"] = types.SimpleNamespace(
        publish=lambda pose: published.append({"x": pose.x, "y": pose.y, "theta": pose.theta}))
    pose = {"x": wire.Float32(1.5), "y": wire.Float32(2.5), "theta": wire.Float32(0.5)}
    results = []
    for form in (wire.WireForm.FINAL, wire.WireForm.MAP):
        data = wire.encode_datagram("odometry_raw", pose, form=form)

        def run() -> Any:
            published.clear()
            name, args = msg.decode(data)
            namespace["odometry_raw_cb"](args)
            return {"name": name, "published": published[-1]}
        results.append({"id": f"master_publisher_{form.value}", "decoder": "odometry_raw_cb(message.decode(micros_rt's "
                        f"{form.value}-form Pose2D datagram)[1])", "input_hex": data.hex(),
                        "code": f"{path}@{commit[:8]} with {ERAS['final'][1]['message'][1]}@babf2cfa", **outcome(run)})
    return {"repository": "https://github.com/cvra/cvra_debra_ros", "commit": commit, "files": {"master_publisher":
            f"{path}@{commit}"}, "captured_with": "scripts/capture_cvra_fixtures.py --debra (rospy and cvra_msgs "
            "stubbed: Pose2D is a plain object, publish records x, y, theta)", "entries": results}


def main(argv: Optional[List[str]] = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("repo", type=Path, help="a clone of cvra/robot-software (work tree or git directory)")
    ap.add_argument("--out", type=Path, default=ROOT / "tests" / "fixtures" / "cvra")
    ap.add_argument("--check", action="store_true", help="compare with the files there; write nothing")
    ap.add_argument("--debra", type=Path, help="a clone of cvra/cvra_debra_ros: also run its master_publisher.py's "
                                               "odometry_raw callback on micros_rt's datagrams")
    args = ap.parse_args(argv)
    differ = 0
    with tempfile.TemporaryDirectory(prefix="cvra_rpc_") as tmp:
        jobs: List[Tuple[str, Callable[[], Dict[str, Any]]]] = [
            (f"{era}_{commit[:8]}", functools.partial(capture, args.repo, era, Path(tmp)))
            for era, (commit, _, _) in ERAS.items()]
        if args.debra is not None:
            jobs.append((f"debra_master_publisher_{DEBRA_COMMIT[:7]}",
                         functools.partial(capture_debra, args.debra, args.repo, Path(tmp))))
        for stem, job in jobs:
            data = job()
            commit = data["commit"]
            path = args.out / f"{stem}.json"
            text = json.dumps(data, indent=1) + "\n"
            if args.check:
                same = path.exists() and json.loads(path.read_text())["entries"] == data["entries"]
                differ += not same
                print(f"{path}: {'same' if same else 'DIFFERENT'}")
            else:
                args.out.mkdir(parents=True, exist_ok=True)
                path.write_text(text)
                print(f"{path}: {len(data['entries'])} entries from {commit[:8]}")
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main())
