"""The bridge configuration: the issue's example, defaults, and errors naming file, line and key."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from micros_rt import TransportPriority
from micros_rt.bridges.mcu.config import load_config, parse_config
from micros_rt.transports.mcu.wire import WireForm
from micros_rt.transports.mcu.errors import McuConfigError

ISSUE_EXAMPLE = """\
microcontroller: {address: 127.0.0.2, topic_port: 20000, service_port: 20001}   # the board
bind: {address: 127.0.0.1, topic_port: 20000, service_port: 20001}              # the bridge
mtu: 1472
to_microcontroller:
  - {topic: /cmd_vel, type: geometry_msgs/Twist}
from_microcontroller:
  - {topic: /imu, type: sensor_msgs/Imu, name: imu, qos: {deadline: 0.5}}
services_on_microcontroller:
  - {service: /mcu/reset, type: std_srvs/Trigger, name: reset}
services_for_microcontroller:
  - {service: /set_mode, type: std_srvs/SetBool, name: set_mode}
"""


def test_the_issue_example(tmp_path: Path) -> None:
    path = tmp_path / "mcu.yaml"
    path.write_text(ISSUE_EXAMPLE)
    cfg = load_config(path)
    assert cfg.microcontroller.topic() == ("127.0.0.2", 20000) and cfg.bind.service() == ("127.0.0.1", 20001)
    (cmd,) = cfg.to_microcontroller
    assert cmd.name == "geometry_msgs/Twist" and cmd.data_class._type == "geometry_msgs/Twist"  # name defaults
    (imu,) = cfg.from_microcontroller
    assert imu.name == "imu" and imu.subscribe.deadline == 0.5 and imu.line == 7
    assert imu.subscribe.using_best_effort_protocol  # the link is best effort
    assert cfg.services_on_microcontroller[0].service_class._type == "std_srvs/Trigger"
    assert cfg.services_for_microcontroller[0].timeout == 2.0


def test_defaults() -> None:
    cfg = parse_config("microcontroller: {address: 10.0.0.7}")
    assert cfg.microcontroller.topic_port == 20000 and cfg.microcontroller.service_port == 20001
    assert cfg.bind.address == "0.0.0.0" and cfg.bind.topic_port == 20000 and cfg.mtu == 1472
    assert cfg.to_microcontroller == () and cfg.stats_period == 1.0
    assert cfg.wire_form is None  # learned from the board (CVRA's final form until it has sent anything)


def test_wire_form_per_board() -> None:
    assert parse_config("microcontroller: {address: 10.0.0.7}\nwire_form: readme").wire_form is WireForm.README
    assert parse_config("microcontroller: {address: 10.0.0.7}\nwire_form: cvra").wire_form is WireForm.FINAL


def test_qos_on_entries() -> None:
    cfg = parse_config("""\
microcontroller: {address: 10.0.0.7}
to_microcontroller:
  - topic: /cmd_vel
    type: geometry_msgs/Twist
    qos: {transport_priority: HIGH, msg_valid_period: 0.2, time_filter_duration: 0.1, using_best_effort_protocol: true}
services_on_microcontroller:
  - {service: /reset, type: std_srvs/Trigger, timeout: 0.5, qos: {transport_priority: VeryHigh}}
""")
    cmd = cfg.to_microcontroller[0]
    assert cmd.advertise.transport_priority is TransportPriority.HIGH and cmd.advertise.msg_valid_period == 0.2
    assert cmd.subscribe.time_filter_duration == 0.1 and math.isinf(cmd.subscribe.deadline)
    assert cfg.services_on_microcontroller[0].timeout == 0.5
    assert cfg.services_on_microcontroller[0].advertise.transport_priority is TransportPriority.VERY_HIGH


BAD = [
    ("mtu: 1472\n", "mcu.yaml:1: microcontroller: missing"),
    ("microcontroller: {address: 10.0.0.7}\nmtuu: 100\n", "mcu.yaml:2: mtuu: unknown key; known keys: microcontroller"),
    ("microcontroller: {address: board.local}\n", "mcu.yaml:1: microcontroller.address: 'board.local' is invalid"),
    ("microcontroller: {address: 10.0.0.7, topic_port: 70000}\n",
     "mcu.yaml:1: microcontroller.topic_port: 70000 is invalid: expected an integer 1..65535"),
    ("microcontroller: {address: 10.0.0.7}\nmtu: 70000\n", "mcu.yaml:2: mtu: 70000 is invalid"),
    ("microcontroller: {address: 10.0.0.7}\nfrom_microcontroller:\n  - {topic: /imu, type: sensor_msgs/Imu,\n"
     "     qos: {deadline: soon}}\n",
     "mcu.yaml:4: from_microcontroller[0].qos.deadline: 'soon' is invalid: expected a duration"),
    ("microcontroller: {address: 10.0.0.7}\nfrom_microcontroller:\n  - {topic: /imu, type: sensor_msgs/Imu}\n"
     "  - {topic: /imu2, type: sensor_msgs/Imu}\n",
     "mcu.yaml:4: from_microcontroller[1].name: stream name 'sensor_msgs/Imu' is already used by the entry on line 3"),
    ("microcontroller: {address: 10.0.0.7}\nto_microcontroller:\n  - {topic: /cmd, type: geometry_msgs/Twistt}\n",
     "mcu.yaml:3: to_microcontroller[0].type: unknown message type 'geometry_msgs/Twistt'"),
    ("microcontroller: {address: 10.0.0.7}\nto_microcontroller:\n  - {topic: /cmd, type: geometry_msgs/Twist,"
     " qos: {deadline: 1.0}}\n",
     "mcu.yaml:3: to_microcontroller[0].qos.deadline: does not apply to to_microcontroller entries"),
    ("microcontroller: {address: 10.0.0.7}\nto_microcontroller:\n  - {topic: /cmd, type: geometry_msgs/Twist,"
     " colour: red}\n", "mcu.yaml:3: to_microcontroller[0].colour: unknown key"),
    ("microcontroller: {address: 10.0.0.7}\nservices_on_microcontroller:\n  - {service: /r, type: std_srvs/Trigga}\n",
     "mcu.yaml:3: services_on_microcontroller[0].type: unknown service type 'std_srvs/Trigga'"),
    ("microcontroller: {address: 10.0.0.7}\nservices_on_microcontroller:\n  - {service: /r, type: std_srvs/Trigger,"
     " timeout: 0}\n", "mcu.yaml:3: services_on_microcontroller[0].timeout: 0 is invalid"),
    ("microcontroller: {address: 10.0.0.7}\nto_microcontroller:\n  - {topic: 'bad name', type: std_msgs/String}\n",
     "mcu.yaml:3: to_microcontroller[0].topic: 'bad name' is not a legal ROS name"),
    ("microcontroller: {address: 10.0.0.7}\nbind: {address: '::1'}\n", "must both be IPv4 or both IPv6"),
    ("microcontroller: {address: 10.0.0.7}\nwire_form: array\n",
     "mcu.yaml:2: wire_form: 'array' is invalid: expected the form the board's firmware speaks -- final"),
    ("microcontroller: {address: 10.0.0.7}\nto_microcontroller:\n  - {topic: /cmd, type: geometry_msgs/Twist,"
     " qos: {data_centric_update: true}}\n", "mcu.yaml:3: to_microcontroller[0].qos.data_centric_update: does not"),
]


@pytest.mark.parametrize("text, words", BAD)
def test_errors_name_file_line_and_key(text: str, words: str) -> None:
    with pytest.raises(McuConfigError) as info:
        parse_config(text, source="mcu.yaml")
    assert words in str(info.value)


def test_reliable_delivery_on_the_link_is_refused_in_words() -> None:
    text = ("microcontroller: {address: 10.0.0.7}\nfrom_microcontroller:\n"
            "  - {topic: /imu, type: sensor_msgs/Imu, qos: {using_best_effort_protocol: false}}\n")
    with pytest.raises(McuConfigError) as info:
        parse_config(text, source="mcu.yaml")
    text_of_error = str(info.value)
    assert text_of_error.startswith("mcu.yaml:3: from_microcontroller[0].qos.using_best_effort_protocol: reliable")
    assert "best effort only" in text_of_error and "use a service" in text_of_error


def test_unreadable_file_names_it(tmp_path: Path) -> None:
    with pytest.raises(McuConfigError, match="nope.yaml: cannot read the bridge configuration: "):
        load_config(tmp_path / "nope.yaml")
    (tmp_path / "empty.yaml").write_text("")
    with pytest.raises(McuConfigError, match=r"empty.yaml: empty configuration; at least 'microcontroller: \{"):
        load_config(tmp_path / "empty.yaml")
