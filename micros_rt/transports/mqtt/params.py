"""mqtt_client's connection parameters (``broker``, ``client``), validated, with mqtt_client's defaults: what
the MQTT connection (:mod:`.client`) and the profile back end (:mod:`.backend`) need. The bridge's topic
mappings (``bridge.ros2mqtt[]``, ``bridge.mqtt2ros[]``) and its params file are
:mod:`micros_rt.bridges.mqtt.params`, which reads them with :class:`ParamsReader` too.

A parameter that has a default and is not set is logged as mqtt_client logs it (``Parameter 'client/id' not
set, defaulting to ''``). Unknown keys and bad values are errors naming the parameter, where mqtt_client
would ignore or misread them.

micros_rt additions (never needed by an mqtt_client params file): ``client.buffer.max_age`` (seconds a
buffered message stays valid, 0 = forever) and ``client.max_packet_size`` (bytes; larger messages are
dropped and counted instead of making the broker close the connection, as AimRT's ``max_pkg_size_k``).
``mqtt_client_version`` (:func:`parse_wire`, micros_rt; ``2`` or ``1``) fixes the mqtt_client wire written.

>>> r = ParamsReader("params")
>>> broker, client = parse_connection(r, {"broker": {"port": 1884}})
>>> broker.port, r.warnings[0]
(1884, "Parameter 'broker/tls/enabled' not set, defaulting to '0'")
"""

from __future__ import annotations

import dataclasses
import os
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple

from ...exceptions import MicrosRtError
from .codec import WireGeneration

__all__ = [
    "BrokerParams",
    "ClientParams",
    "ConnectionParams",
    "ParamsError",
    "ParamsReader",
    "parse_connection",
    "parse_wire",
    "resolve_path",
]


class ParamsError(MicrosRtError, ValueError):
    """A bad parameter file or value; the message names the file and the parameter."""


@dataclasses.dataclass(frozen=True)
class BrokerParams:
    """``broker.*``"""

    host: str = "localhost"
    port: int = 1883
    user: str = ""
    password: str = ""
    tls_enabled: bool = False
    tls_ca_certificate: str = "/etc/ssl/certs/ca-certificates.crt"


@dataclasses.dataclass(frozen=True)
class ClientParams:
    """``client.*``"""

    id: str = ""
    buffer_size: int = 0
    buffer_directory: str = "buffer"
    buffer_max_age: float = 0.0
    last_will_topic: str = ""
    last_will_message: str = "offline"
    last_will_qos: int = 0
    last_will_retained: bool = False
    clean_session: bool = True
    keep_alive_interval: float = 60.0
    max_inflight: int = 65535
    max_packet_size: int = 0
    tls_certificate: str = ""
    tls_key: str = ""
    tls_password: str = ""

    @property
    def buffer_enabled(self) -> bool:
        """mqtt_client buffers only with a client id (and a size above 0)."""
        return bool(self.id) and self.buffer_size > 0


@dataclasses.dataclass(frozen=True)
class ConnectionParams:
    """What a connection to the broker needs: ``broker.*`` and ``client.*``."""

    broker: BrokerParams
    client: ClientParams


class ParamsReader:
    """Reads mqtt_client-style parameters out of a parsed YAML mapping: values checked by kind and range
    (:meth:`get`), unknown keys refused (:meth:`check_keys`), and the defaults used collected in
    :attr:`warnings` as mqtt_client logs them. Errors are :class:`ParamsError` naming ``source`` and the
    parameter (``broker/port``)."""

    def __init__(self, source: str) -> None:
        self.source = source
        self.warnings: List[str] = []

    def fail(self, name: str, problem: str) -> ParamsError:
        """The error for parameter ``name``: ``<source>: parameter '<name>' <problem>``."""
        return ParamsError(f"{self.source}: parameter '{name}' {problem}")

    def section(self, data: Mapping[str, Any], key: str, name: str) -> Mapping[str, Any]:
        """The mapping under ``key`` (empty when unset)."""
        value = data.get(key)
        if value is None:
            return {}
        if not isinstance(value, Mapping):
            raise self.fail(name, f"must be a mapping of parameters, got {value!r}")
        return value

    def check_keys(self, data: Mapping[str, Any], allowed: Sequence[str], name: str) -> None:
        """Refuse keys of ``data`` not in ``allowed`` (``name``: where ``data`` is, "" for the top level)."""
        unknown = [str(k) for k in data if k not in allowed]
        if unknown:
            where = f"'{name}'" if name else "the top level"
            raise ParamsError(f"{self.source}: unknown parameter(s) {', '.join(repr(u) for u in unknown)} in "
                              f"{where} (allowed: {', '.join(allowed)})")

    def get(self, data: Mapping[str, Any], key: str, name: str, kind: type, default: Any = None, *,
            warn: bool = True, lo: Optional[float] = None, hi: Optional[float] = None) -> Any:
        """The value of ``key`` as ``kind`` (bool, int, float, str); ``default`` (logged) when unset."""
        value = data.get(key)
        if value is None:
            if default is not None and warn:
                self.warnings.append(f"Parameter '{name}' not set, defaulting to '{_c_style(default)}'")
            return default
        if kind is bool:
            if not isinstance(value, bool):
                raise self.fail(name, f"must be true or false, got {value!r}")
        elif kind is int:
            if isinstance(value, bool) or not isinstance(value, int):
                raise self.fail(name, f"must be an integer, got {value!r}")
        elif kind is float:
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise self.fail(name, f"must be a number (seconds), got {value!r}")
            value = float(value)
        elif kind is str:
            if isinstance(value, (int, float)) and not isinstance(value, bool):
                value = str(value)          # YAML reads a numeric password or client id as a number
            if not isinstance(value, str):
                raise self.fail(name, f"must be a string, got {value!r}")
        if isinstance(value, (int, float)) and (lo is not None and value < lo or hi is not None and value > hi):
            raise self.fail(name, f"is {value!r}, must be between {lo:g} and {hi:g}")
        return value


def _c_style(value: Any) -> str:
    """Defaults as mqtt_client's log shows them (C++ formatting): true -> 1, 60.0 -> 60.000000."""
    if isinstance(value, bool):
        return "1" if value else "0"
    if isinstance(value, float):
        return f"{value:.6f}"
    return str(value)


def parse_connection(r: "ParamsReader", data: Mapping[str, Any]) -> Tuple[BrokerParams, ClientParams]:
    """The ``broker`` and ``client`` sections (shared by the bridge and the MQTT back end)."""
    b = r.section(data, "broker", "broker")
    r.check_keys(b, ("host", "port", "user", "pass", "tls"), "broker")
    btls = r.section(b, "tls", "broker/tls")
    r.check_keys(btls, ("enabled", "ca_certificate"), "broker/tls")
    user = r.get(b, "user", "broker/user", str, "", warn=False)
    tls_enabled = r.get(btls, "enabled", "broker/tls/enabled", bool, False)
    broker = BrokerParams(
        host=r.get(b, "host", "broker/host", str, "localhost"),
        port=r.get(b, "port", "broker/port", int, 1883, lo=1, hi=65535),
        user=user,
        password=r.get(b, "pass", "broker/pass", str, "", warn=bool(user)),
        tls_enabled=tls_enabled,
        tls_ca_certificate=r.get(btls, "ca_certificate", "broker/tls/ca_certificate", str,
                                 "/etc/ssl/certs/ca-certificates.crt", warn=tls_enabled),
    )

    c = r.section(data, "client", "client")
    r.check_keys(c, ("id", "buffer", "last_will", "clean_session", "keep_alive_interval", "max_inflight",
                     "max_packet_size", "tls"), "client")
    cbuf = r.section(c, "buffer", "client/buffer")
    r.check_keys(cbuf, ("size", "directory", "max_age"), "client/buffer")
    will = r.section(c, "last_will", "client/last_will")
    r.check_keys(will, ("topic", "message", "qos", "retained"), "client/last_will")
    ctls = r.section(c, "tls", "client/tls")
    unsupported = [k for k in ("version", "verify", "alpn_protos") if k in ctls]
    if unsupported:
        raise r.fail(f"client/tls/{unsupported[0]}",
                     "(mqtt_client 2.x) is not supported: micros_rt negotiates the highest TLS version both sides "
                     "support, always verifies the broker's certificate and host name against 'broker/tls/ca_certificate' and "
                     "sends no ALPN protocols; remove the key")
    r.check_keys(ctls, ("certificate", "key", "password"), "client/tls")
    client_id = r.get(c, "id", "client/id", str, "")
    if not client_id:
        r.warnings.append("Client buffer can not be enabled when client ID is empty")
    will_topic = r.get(will, "topic", "client/last_will/topic", str, "", warn=False)
    client = ClientParams(
        id=client_id,
        buffer_size=r.get(cbuf, "size", "client/buffer/size", int, 0, warn=bool(client_id), lo=0, hi=10_000_000),
        buffer_directory=r.get(cbuf, "directory", "client/buffer/directory", str, "buffer", warn=bool(client_id)),
        buffer_max_age=r.get(cbuf, "max_age", "client/buffer/max_age", float, 0.0, warn=False, lo=0, hi=1e9),
        last_will_topic=will_topic,
        last_will_message=r.get(will, "message", "client/last_will/message", str, "offline", warn=bool(will_topic)),
        last_will_qos=r.get(will, "qos", "client/last_will/qos", int, 0, warn=bool(will_topic), lo=0, hi=2),
        last_will_retained=r.get(will, "retained", "client/last_will/retained", bool, False, warn=bool(will_topic)),
        clean_session=r.get(c, "clean_session", "client/clean_session", bool, True),
        keep_alive_interval=r.get(c, "keep_alive_interval", "client/keep_alive_interval", float, 60.0,
                                  lo=0, hi=65535),
        max_inflight=r.get(c, "max_inflight", "client/max_inflight", int, 65535, lo=1, hi=65535),
        max_packet_size=r.get(c, "max_packet_size", "client/max_packet_size", int, 0, warn=False, lo=0,
                              hi=268435455),
        tls_certificate=r.get(ctls, "certificate", "client/tls/certificate", str, "", warn=False),
        tls_key=r.get(ctls, "key", "client/tls/key", str, "", warn=False),
        tls_password=r.get(ctls, "password", "client/tls/password", str, "", warn=False),
    )
    if bool(client.tls_certificate) != bool(client.tls_key):
        raise r.fail("client/tls/key" if client.tls_certificate else "client/tls/certificate",
                     "must be given together with the other of 'client/tls/certificate' and 'client/tls/key'")
    if client.buffer_size > 0 and not client.id:
        raise r.fail("client/buffer/size", "needs 'client/id': mqtt_client buffers only for a named client")
    return broker, client


def parse_wire(r: "ParamsReader", data: Mapping[str, Any], name: str) -> WireGeneration:
    """``mqtt_client_version``: 2 (default) or 1, also written '2.x'/'1.x'."""
    value = data.get("mqtt_client_version")
    if value is None:
        return WireGeneration.V2
    text = str(value).strip().lower()
    for wire in WireGeneration:
        if not isinstance(value, bool) and text in (str(int(wire)), wire.label, f"{int(wire)}.0"):
            return wire
    raise r.fail(name, f"is {value!r}: the mqtt_client wire to write, 2 (mqtt_client 2.0-2.3, the ROS 1 releases "
                       "installed today; the default) or 1 (mqtt_client 1.0-1.1)")


def resolve_path(path: str, *, env: Optional[Dict[str, str]] = None) -> str:
    """mqtt_client's rule: a relative path is relative to ``ROS_HOME`` (the working directory if unset)."""
    if not path or os.path.isabs(path):
        return path
    environ = os.environ if env is None else env
    return os.path.join(environ.get("ROS_HOME") or os.getcwd(), path)
