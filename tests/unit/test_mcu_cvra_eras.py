"""CVRA's three eras of cvra_rpc, read and written byte for byte (issue 37, items 5-9).

The fixtures in tests/fixtures/cvra/ are the bytes CVRA's own Python code produced, captured by
scripts/capture_cvra_fixtures.py from cvra/robot-software at the commit named in each file (0670b782, the
seed README's era; feb95469, mid-2015; babf2cfa, the final form) and what CVRA's bridge node
(cvra/cvra_debra_ros master_publisher.py) made of micros_rt's datagrams. CVRA's code is not in this
repository; only its output is.
"""

from __future__ import annotations

import json
import socket
import struct
import threading
from pathlib import Path
from typing import Any, Dict, Iterator, List, Optional

import msgpack
import pytest
import roslib.message
from geometry_msgs.msg import Pose2D, Twist, Vector3
from std_msgs.msg import Empty, Float32, String
from std_srvs.srv import SetBool, SetBoolRequest, SetBoolResponse, Trigger, TriggerRequest, TriggerResponse

import harness
from micros_rt.transports.mcu import wire
from micros_rt.bridges.mcu.config import parse_config
from micros_rt.transports.mcu.errors import McuConfigError, McuServiceError, WireError
from micros_rt.transports.mcu.link import McuLink

FIXTURES = Path(__file__).resolve().parent.parent / "fixtures" / "cvra"
LVL = roslib.message.get_service_class("roscpp/SetLoggerLevel")   # an empty response type
BOARD = "127.0.0.2"


def _load(stem: str) -> Dict[str, Any]:
    data: Dict[str, Any] = json.loads((FIXTURES / f"{stem}.json").read_text())
    return data


FINAL = _load("final_babf2cfa")
MID = _load("mid2015_feb95469")
README = _load("readme_0670b782")
DEBRA = _load("debra_master_publisher_947dc49")


def entry(fixture: Dict[str, Any], key: str) -> Dict[str, Any]:
    found: Dict[str, Any] = next(e for e in fixture["entries"] if e["id"] == key)
    return found


def raw(fixture: Dict[str, Any], key: str) -> bytes:
    """The bytes CVRA's code wrote for fixture entry ``key``."""
    e = entry(fixture, key)
    return bytes.fromhex(e["hex"] if "hex" in e else e["input_hex"])


def test_fixtures_name_their_commits() -> None:
    assert FINAL["commit"].startswith("babf2cfa") and MID["commit"].startswith("feb95469")
    assert README["commit"].startswith("0670b782") and DEBRA["commit"].startswith("947dc494")
    for fixture in (FINAL, MID, README):
        assert all("@" in e["code"] for e in fixture["entries"])


# --------------------------------------------------------------------------- item 5: topics from a board

def topic(data: bytes, cls: Any) -> Any:
    name, rest = wire.split_datagram(data)
    return name, wire.codec_for(cls).from_args(rest)


def test_final_list_arguments_publish_a_pose2d() -> None:
    # ["odometry_raw", [1.5, 2.5, 0.5]]: before, "Pose2D in array form needs 3 fields (x, y, theta), got 1"
    data = raw(FINAL, "topic_odometry_raw")
    assert data == bytes.fromhex("92 ac 6f646f6d657472795f726177 93 ca3fc00000 ca40200000 ca3f000000")
    assert topic(data, Pose2D) == ("odometry_raw", Pose2D(x=1.5, y=2.5, theta=0.5))


@pytest.mark.parametrize("fixture, key, cls, want", [
    (FINAL, "topic_speed_bare", Float32, Float32(data=1.5)),        # the firmware's stream_float: bare
    (FINAL, "topic_no_args", Empty, Empty()),                       # encode("foo"): [foo, nil]
    (FINAL, "topic_chatter_map", String, String(data="hi")),        # a map argument
    (MID, "topic_odometry_raw", Pose2D, Pose2D(x=1.5, y=2.5, theta=0.5)),   # [name, x, y, theta]
    (MID, "topic_no_args", Empty, Empty()),                         # [foo]
])
def test_every_eras_topic_datagram_reads(fixture: Dict[str, Any], key: str, cls: Any, want: Any) -> None:
    assert topic(raw(fixture, key), cls)[1] == want


def test_readme_topic_and_nested_arguments_in_any_shape() -> None:
    # the seed README: the name, then a map of fields (two objects)
    data = msgpack.packb("cmd_vel") + msgpack.packb({"linear": {"x": 1.5, "y": 0, "z": 0},
                                                     "angular": {"x": 0, "y": 0, "z": -0.5}})
    want = Twist(linear=Vector3(1.5, 0, 0), angular=Vector3(0, 0, -0.5))
    assert topic(data, Twist) == ("cmd_vel", want)
    # final list arguments with nested messages as arrays or maps
    assert topic(msgpack.packb(["cmd_vel", [[1.5, 0, 0], [0, 0, -0.5]]]), Twist)[1] == want
    assert topic(msgpack.packb(["cmd_vel", [{"x": 1.5, "y": 0, "z": 0}, [0, 0, -0.5]]]), Twist)[1] == want


@pytest.mark.parametrize("data, cls, words", [
    (msgpack.packb(["odometry_raw", 1.5]), Pose2D,
     "one bare value (a float 1.5) can only stand for a type with one field; geometry_msgs/Pose2D has 3 (x, y, theta)"),
    (msgpack.packb(["odometry_raw", [1.5, 2.5]]), Pose2D, "needs 3 fields (x, y, theta), got 2"),
    (msgpack.packb(["speed", "fast"]), Float32, "field 'data' should be a number (float32), got the string 'fast'"),
    (msgpack.packb(["odometry_raw", None]), Pose2D, "field 'x' (geometry_msgs/Pose2D) is missing"),
], ids=["bare_for_3_fields", "list_too_short", "bad_value", "nil_for_3_fields"])
def test_arguments_that_do_not_fit_are_refused_in_words(data: bytes, cls: Any, words: str) -> None:
    with pytest.raises(WireError) as info:
        topic(data, cls)
    assert words in str(info.value)


# --------------------------------------------------------------------------- item 6: bare and nil answers

def answer(data: bytes, service: Any) -> wire.Answer:
    return wire.codec_for(service._response_class).from_answer(wire.decode_response(data))


def test_bare_answers_map_onto_trigger() -> None:
    assert raw(FINAL, "answer_true") == b"\xc3" and raw(FINAL, "answer_pong") == bytes.fromhex("a4706f6e67")
    assert answer(raw(FINAL, "answer_true"), Trigger).response == TriggerResponse(success=True, message="")
    assert answer(raw(FINAL, "answer_pong"), Trigger).response == TriggerResponse(success=True, message="pong")
    assert answer(raw(MID, "answer_pong"), Trigger).response == TriggerResponse(success=True, message="pong")
    assert answer(raw(README, "answer_hello"), Trigger).response == TriggerResponse(True, "Hello, client")
    assert answer(raw(FINAL, "answer_list"), Trigger).response == TriggerResponse(success=True, message="ok")
    assert answer(b"\xc2", SetBool).response == SetBoolResponse(success=False, message="")


def test_nil_answers_an_empty_response_and_is_no_success_for_trigger() -> None:
    nil = raw(FINAL, "c_answer_nil")        # CVRA's C server: nil when the handler wrote nothing
    assert nil == b"\xc0"
    empty = answer(nil, LVL)
    assert empty.response == LVL._response_class() and empty.note is None
    trigger = answer(nil, Trigger)
    assert trigger.response.success is False
    assert "answered nil" in trigger.response.message and "no handler of that name" in trigger.response.message
    with pytest.raises(WireError, match="the answer nil cannot fill a roscpp/GetLoggersResponse, whose fields are loggers"):
        wire.codec_for(roslib.message.get_service_class("roscpp/GetLoggers")._response_class).from_answer(None)


def test_other_bare_answers_for_an_empty_response() -> None:
    assert answer(b"\xc3", LVL).response == LVL._response_class()
    with pytest.raises(WireError, match="answered false"):
        answer(b"\xc2", LVL)
    text = answer(msgpack.packb("parameter x: wrong type"), LVL)  # CVRA's config_update answers errors as text
    assert text.response == LVL._response_class()
    assert text.note is not None and "'parameter x: wrong type'" in text.note


def test_closed_without_an_answer_is_not_an_answer() -> None:
    assert raw(FINAL, "answer_none") == b"" == raw(MID, "answer_none") == raw(README, "answer_none")
    with pytest.raises(WireError) as info:
        wire.decode_response(b"")
    assert info.value.kind == "no_answer"


# --------------------------------------------------------------------------- item 7: requests from a board

def request(frame: bytes, service: Any) -> Any:
    assert frame.endswith(b"\xc0")
    name, rest = wire.decode_request(frame[:-1])
    return name, wire.codec_for(service._request_class).from_request(rest)


@pytest.mark.parametrize("fixture, key, service, want", [
    (README, "call_set_mode_map", SetBool, ("set_mode", SetBoolRequest(data=True))),   # a8 "set_mode" 81 a4 "data" c3
    (README, "call_reset_no_params", Trigger, ("reset", TriggerRequest())),           # a5 "reset" 80
    (MID, "call_set_mode", SetBool, ("set_mode", SetBoolRequest(data=True))),
    (MID, "call_ping_no_params", Trigger, ("ping", TriggerRequest())),
    (FINAL, "call_ping_nil", Trigger, ("ping", TriggerRequest())),
    (FINAL, "call_set_mode_bare", SetBool, ("set_mode", SetBoolRequest(data=True))),
    (FINAL, "call_set_mode_list", SetBool, ("set_mode", SetBoolRequest(data=True))),
    (FINAL, "call_lvl_list", LVL, ("lvl", LVL._request_class(logger="ros", level="debug"))),
])
def test_every_eras_request_reads(fixture: Dict[str, Any], key: str, service: Any, want: Any) -> None:
    assert request(raw(fixture, key), service) == want


def test_readme_request_is_two_objects_in_one_frame() -> None:
    frame = raw(README, "call_set_mode_map")
    assert wire.unframe(frame[:-1]) == bytes.fromhex("a8 7365745f6d6f6465 81 a4 64617461 c3")


# --------------------------------------------------------------------------- item 9: what micros_rt writes

def test_micros_rt_writes_what_each_eras_own_code_writes() -> None:
    f = wire.WireForm
    on = {"data": True}
    assert wire.encode_request("set_mode", on, form=f.README) == raw(README, "call_set_mode_map")
    assert wire.encode_request("reset", {}, form=f.README) == raw(README, "call_reset_no_params")
    assert wire.encode_request("set_mode", on, form=f.MID2015) == raw(MID, "call_set_mode")
    assert wire.encode_request("ping", {}, form=f.MID2015) == raw(MID, "call_ping_no_params")
    assert wire.encode_request("ping", {}) == raw(FINAL, "call_ping_nil")            # the default: final
    assert wire.encode_request("set_mode", on) == raw(FINAL, "call_set_mode_bare")
    assert wire.encode_request("lvl", {"logger": "ros", "level": "debug"}) == raw(FINAL, "call_lvl_list")
    speed = wire.codec_for(Float32).to_wire(Float32(data=1.5))
    assert wire.encode_datagram("speed", speed) == raw(FINAL, "topic_speed_bare")
    assert wire.encode_datagram("foo", {}) == raw(FINAL, "topic_no_args")
    assert wire.encode_datagram("foo", {}, form=f.MID2015) == raw(MID, "topic_no_args")
    # Pose2D's fields are float64 (CVRA packs float32): the same values, in the same shape
    pose = wire.codec_for(Pose2D).to_wire(Pose2D(1.5, 2.5, 0.5))
    assert msgpack.unpackb(wire.encode_datagram("odometry_raw", pose)) == msgpack.unpackb(
        raw(FINAL, "topic_odometry_raw"))
    assert msgpack.unpackb(wire.encode_datagram("odometry_raw", pose, form=f.MID2015)) == msgpack.unpackb(
        raw(MID, "topic_odometry_raw"))
    answer_fields = wire.codec_for(TriggerResponse).to_wire(TriggerResponse(True, "ok"))
    assert wire.encode_response(answer_fields) == raw(FINAL, "answer_list")


def test_cvras_decoders_give_their_handlers_positional_arguments() -> None:
    """What CVRA's decode/decode_call returned for micros_rt's bytes (captured), and that micros_rt still writes
    those bytes: a handler gets None, True or a list, as from a CVRA client, never a map."""
    f = wire.WireForm
    pose = {"x": wire.Float32(1.5), "y": wire.Float32(2.5), "theta": wire.Float32(0.5)}
    for fixture, form in ((FINAL, f.FINAL), (MID, f.MID2015)):
        assert wire.encode_datagram("odometry_raw", pose, form=form) == raw(fixture, "decode_micros_rt_pose2d")
        assert wire.encode_request("set_mode", {"data": True}, form=form) == raw(fixture, "decode_call_micros_rt_set_mode")
        assert wire.encode_request("reset", {}, form=form) == raw(fixture, "decode_call_micros_rt_empty")
    assert entry(FINAL, "decode_micros_rt_pose2d")["returns"] == ["odometry_raw", [1.5, 2.5, 0.5]]
    assert entry(FINAL, "decode_call_micros_rt_set_mode")["returns"] == ["set_mode", True]
    assert entry(FINAL, "decode_call_micros_rt_empty")["returns"] == ["reset", None]
    assert entry(MID, "decode_call_micros_rt_set_mode")["returns"] == ["set_mode", [True]]
    assert entry(MID, "decode_call_micros_rt_empty")["returns"] == ["reset", []]
    # the map form (micros_rt's default before) reached a final-era handler as a map: {'data': True}
    assert entry(FINAL, "decode_call_micros_rt_map")["returns"] == ["set_mode", {"data": True}]
    # the seed README's era: its decode_call reads micros_rt's readme request; the one before made it raise
    ours = wire.encode_request("set_mode", {"data": True}, form=f.README)
    assert ours == raw(README, "decode_call_micros_rt_readme")
    assert entry(README, "decode_call_micros_rt_readme")["returns"] == ["set_mode", {"data": True}]
    assert "not enough values to unpack (expected 2, got 1)" in entry(README, "handle_connection_micros_rt_before")[
        "raises"]


def test_cvras_bridge_node_publishes_micros_rts_default_datagram() -> None:
    """cvra_debra_ros master_publisher.py's odometry_raw_cb (x, y, theta = tuple(args)) on micros_rt's datagram."""
    final = entry(DEBRA, "master_publisher_final")
    pose = wire.codec_for(Pose2D).to_wire(Pose2D(1.5, 2.5, 0.5))
    assert msgpack.unpackb(wire.encode_datagram("odometry_raw", pose)) == msgpack.unpackb(
        bytes.fromhex(final["input_hex"]))
    assert final["returns"] == {"name": "odometry_raw", "published": {"x": 1.5, "y": 2.5, "theta": 0.5}}
    # the map form unpacks the map's keys: the node would publish x='x', y='y', theta='theta'
    assert entry(DEBRA, "master_publisher_map")["returns"]["published"] == {"x": "x", "y": "y", "theta": "theta"}


def test_final_form_nests_messages_as_arrays() -> None:
    twist = wire.codec_for(Twist).to_wire(Twist(linear=Vector3(1.5, 0, 0), angular=Vector3(0, 0, -0.5)))
    assert msgpack.unpackb(wire.encode_datagram("cmd_vel", twist)) == ["cmd_vel", [[1.5, 0, 0], [0, 0, -0.5]]]
    assert msgpack.unpackb(wire.encode_datagram("cmd_vel", twist, form=wire.WireForm.MID2015)) == [
        "cmd_vel", [1.5, 0, 0], [0, 0, -0.5]]


# --------------------------------------------------------------------------- the wire_form key

@pytest.mark.parametrize("value, form", [
    ("final", "FINAL"), ("cvra", "FINAL"), ("babf2cfa", "FINAL"), ("mid2015", "MID2015"), ("feb95469", "MID2015"),
    ("readme", "README"), ("'0670b782'", "README"), ("map", "MAP"),
])
def test_wire_form_names_an_era(value: str, form: str) -> None:
    assert parse_config(f"microcontroller: {{address: 10.0.0.7}}\nwire_form: {value}").wire_form is getattr(
        wire.WireForm, form)


def test_wire_form_default_is_learned_and_a_bad_value_lists_the_eras() -> None:
    assert parse_config("microcontroller: {address: 10.0.0.7}").wire_form is None   # the board's era
    assert wire.DEFAULT_WIRE_FORM is wire.WireForm.FINAL                             # until it sends any
    with pytest.raises(McuConfigError) as info:
        parse_config("microcontroller: {address: 10.0.0.7}\nwire_form: 2016\n", source="mcu.yaml")
    text = str(info.value)
    assert text.startswith("mcu.yaml:2: wire_form: 2016 is invalid: expected the form the board's firmware speaks")
    for word in ("final (CVRA's last cvra_rpc", "mid2015", "readme (the seed README, 0670b782", "map ([name, {fields}]"):
        assert word in text


# --------------------------------------------------------------------------- item 8: the link, closed connections

class Board:
    """A board's service port on loopback: each accepted call gets ``answers[i]`` (None: close unanswered)."""

    def __init__(self, answers: List[Optional[bytes]]) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.sock.bind((BOARD, 0))
        self.sock.listen(4)
        self.port = int(self.sock.getsockname()[1])
        self.answers = answers
        self.requests: List[bytes] = []
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _serve(self) -> None:
        for answer in self.answers:
            conn, _ = self.sock.accept()
            with conn:
                conn.settimeout(10)
                data = b""
                while not data.endswith(b"\xc0"):
                    chunk = conn.recv(4096)
                    if not chunk:
                        break
                    data += chunk
                self.requests.append(data)
                if answer is not None:
                    conn.sendall(answer)
                else:  # close at once, with a reset-free FIN
                    conn.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 0, 0))

    def close(self) -> None:
        self.thread.join(10)
        self.sock.close()


@pytest.fixture
def link_to() -> Iterator[Any]:
    made: List[Any] = []

    def make(board: Board, form: str = "final") -> McuLink:
        cfg = parse_config(
            f"microcontroller: {{address: {BOARD}, service_port: {board.port}}}\n"
            f"bind: {{address: 127.0.0.1, topic_port: {harness.free_tcp_port()}, service_port: "
            f"{harness.free_tcp_port()}}}\nwire_form: {form}\n"
            "services_on_microcontroller:\n"
            "  - {service: /lvl, type: roscpp/SetLoggerLevel, name: lvl, timeout: 5}\n"
            "  - {service: /reset, type: std_srvs/Trigger, name: reset, timeout: 5}\n", source="t.yaml")
        link = McuLink(cfg)
        made.append((link, board))
        return link
    yield make
    for link, board in made:
        link.close()
        board.close()


def services(link: McuLink) -> Dict[str, Any]:
    return {e.name: e for e in link.config.services_on_microcontroller}


def test_a_closed_connection_is_an_error_for_every_response_type(link_to: Any) -> None:
    board = Board([None, None, b"\xc0", b"\xc0"])
    link = link_to(board)
    entries = services(link)
    for name, params in (("lvl", {"logger": "ros", "level": "debug"}), ("reset", {})):
        with pytest.raises(McuServiceError) as info:
            link.call(entries[name], params)
        assert f"closed the connection without answering /{name} ('{name}')" in str(info.value)
    # nil answers: the empty response is answered, Trigger is no success
    lvl = wire.codec_for(LVL._response_class).from_answer(link.call(entries["lvl"], {"logger": "ros", "level": "x"}))
    assert lvl.response == LVL._response_class()
    reset = wire.codec_for(TriggerResponse).from_answer(link.call(entries["reset"], {}))
    assert reset.response.success is False
    board.close()
    assert link.stats.get("services_on_microcontroller", "failed", entry="lvl") == 1
    assert link.stats.get("services_on_microcontroller", "failed", entry="reset") == 1
    # what the final-era board received: [name, [logger, level]] and [name, nil], as CVRA's clients send
    assert [wire.decode_request(r[:-1]) for r in board.requests] == [
        ("lvl", [["ros", "debug"]]), ("reset", [None]), ("lvl", [["ros", "x"]]), ("reset", [None])]


def test_a_readme_era_board_gets_two_objects(link_to: Any) -> None:
    board = Board([msgpack.packb("Hello, client")])
    link = link_to(board, "readme")
    got = link.call(services(link)["reset"], {})
    board.close()
    assert wire.codec_for(TriggerResponse).from_answer(got).response == TriggerResponse(True, "Hello, client")
    assert board.requests == [raw(README, "call_reset_no_params")]   # byte for byte what 0670b782's client sends


def test_a_board_calling_in_each_eras_form_is_served(link_to: Any) -> None:
    board = Board([])
    cfg_text = (f"microcontroller: {{address: {BOARD}}}\nbind: {{address: 127.0.0.1, topic_port: "
                f"{harness.free_tcp_port()}, service_port: {harness.free_tcp_port()}}}\n"
                "services_for_microcontroller:\n  - {service: /set_mode, type: std_srvs/SetBool, name: set_mode}\n")
    link = McuLink(parse_config(cfg_text, source="t.yaml"))
    board.close()
    seen: List[Any] = []

    def handler(entry_: Any, rest: List[Any]) -> Dict[str, Any]:
        seen.append(wire.codec_for(SetBool._request_class).from_request(rest))
        return {"success": True, "message": "mode on"}
    try:
        link.serve_calls(handler)
        answers = []
        for frame in (raw(README, "call_set_mode_map"), raw(MID, "call_set_mode"), raw(FINAL, "call_set_mode_bare"),
                      raw(FINAL, "call_set_mode_list")):
            with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as c:
                c.bind((BOARD, 0))
                c.settimeout(10)
                c.connect(("127.0.0.1", link.config.bind.service_port))
                c.sendall(frame)
                data = b""
                while True:
                    chunk = c.recv(4096)
                    if not chunk:
                        break
                    data += chunk
                answers.append(data)
    finally:
        link.close()
    assert seen == [SetBoolRequest(data=True)] * 4
    assert answers == [bytes.fromhex("92 c3 a7 6d6f6465206f6e")] * 4       # [True, "mode on"], as CVRA answers
    assert link.stats.get("services_for_microcontroller", "ok", entry="set_mode") == 4



# --------------------------------------------------------------------------- issue 44: the board's era, learned

@pytest.mark.parametrize("fixture, key, request_of, form", [
    (FINAL, "topic_odometry_raw", Pose2D, "FINAL"), (FINAL, "topic_no_args", Empty, "FINAL"),
    (FINAL, "call_ping_nil", TriggerRequest, "FINAL"), (FINAL, "call_lvl_list", LVL._request_class, "FINAL"),
    (FINAL, "topic_speed_bare", Float32, None), (FINAL, "call_set_mode_bare", SetBoolRequest, None),
    (MID, "topic_odometry_raw", Pose2D, "MID2015"), (MID, "topic_no_args", Empty, "MID2015"),
    (MID, "call_ping_no_params", TriggerRequest, "MID2015"), (MID, "call_set_mode", SetBoolRequest, None),
    (README, "call_set_mode_map", SetBoolRequest, "README"), (README, "call_reset_no_params", TriggerRequest, "README"),
])
def test_each_eras_own_bytes_name_its_era(fixture: Dict[str, Any], key: str, request_of: Any,
                                          form: Optional[str]) -> None:
    data = raw(fixture, key)
    payload = wire.decode_request_payload(data[:-1]) if key.startswith("call") else wire.split_payload(data)
    want = None if form is None else getattr(wire.WireForm, form)
    # a one-field type's [name, value] is the final and the mid-2015 form alike: it names no era
    assert payload.form(wire.codec_for(request_of).field_count) is want


def test_a_link_without_wire_form_writes_the_era_the_board_showed(link_to: Any) -> None:
    """A mid-2015 board streams its Pose2D as [name, x, y, theta]: the link then calls it in that form
    ([name] for no arguments, [name, f1, f2] for two), where CVRA's final form would hand its handler [None]
    and [['ros', 'debug']]; before the board has sent anything, the final form is written."""
    board = Board([b"\xc0", b"\xc0", b"\xc0"])
    topic_port = harness.free_tcp_port()
    cfg = parse_config(
        f"microcontroller: {{address: {BOARD}, service_port: {board.port}}}\n"
        f"bind: {{address: 127.0.0.1, topic_port: {topic_port}, service_port: {harness.free_tcp_port()}}}\n"
        "from_microcontroller:\n  - {topic: /odometry, type: geometry_msgs/Pose2D, name: odometry_raw}\n"
        "services_on_microcontroller:\n"
        "  - {service: /lvl, type: roscpp/SetLoggerLevel, name: lvl, timeout: 5}\n"
        "  - {service: /reset, type: std_srvs/Trigger, name: reset, timeout: 5}\n", source="t.yaml")
    link = McuLink(cfg)
    try:
        reader = link.open_reader(cfg.from_microcontroller[0])
        assert link.wire_form is wire.WireForm.FINAL and link.stats.snapshot()["link"]["wire_form"] == "final"
        link.call(services(link)["reset"], {})                               # nothing heard yet: the default
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as udp:
            udp.bind((BOARD, 0))
            udp.sendto(raw(MID, "topic_odometry_raw"), ("127.0.0.1", topic_port))
            harness.wait_until(lambda: link.wire_form is wire.WireForm.MID2015, 10,
                               message="the link to learn the mid-2015 form")
        assert reader.take(10)[0][0].theta == 0.5
        link.call(services(link)["reset"], {})
        link.call(services(link)["lvl"], {"logger": "ros", "level": "debug"})
    finally:
        link.close()
        board.close()
    assert [wire.decode_request(r[:-1]) for r in board.requests] == [
        ("reset", [None]), ("reset", []), ("lvl", ["ros", "debug"])]
    assert board.requests[1] == raw(MID, "decode_call_micros_rt_empty")       # byte for byte mid-2015's
    assert link.stats.snapshot()["link"] == {"wire_form": "mid2015", "wire_form_changes": 1}


def test_any_object_after_a_name_or_as_an_answer_only_ever_raises_wire_error() -> None:
    """Nothing malformed escapes as another exception (the link counts WireError and goes on)."""
    import random

    from sensor_msgs.msg import Imu

    rnd = random.Random(37)
    leaves: List[Any] = [None, True, False, 0, -1, 2**40, 1.5, float("nan"), "", "pong", b"\x01", "x" * 40]

    def any_object(depth: int = 0) -> Any:
        kind = rnd.randrange(5 if depth < 3 else 1)
        if kind == 0:
            return rnd.choice(leaves)
        if kind in (1, 2):
            return [any_object(depth + 1) for _ in range(rnd.randrange(5))]
        if kind == 3:
            return {rnd.choice(["x", "y", "theta", "success", "message", "data", 1]): any_object(depth + 1)
                    for _ in range(rnd.randrange(4))}
        return rnd.choice([[1.5, 2.5, 0.5], {"x": 1, "y": 2, "theta": 3}, [[0, [1, 2], "f"]]])

    readers = [wire.codec_for(c) for c in (Pose2D, Imu, Empty, Float32, String, Twist)]
    answers = [wire.codec_for(s._response_class) for s in (Trigger, SetBool, LVL,
                                                           roslib.message.get_service_class("roscpp/GetLoggers"))]
    read = failed = 0
    for _ in range(20_000):
        obj = any_object()
        rest = obj if isinstance(obj, list) and rnd.random() < 0.5 else [obj]
        for codec in readers:
            try:
                codec.from_args(rest)
                read += 1
            except WireError:
                failed += 1
        for codec in answers:
            try:
                codec.from_answer(obj)
                read += 1
            except WireError:
                failed += 1
    assert read > 1000 and failed > 1000
