"""A real mosquitto broker for tests: loopback, a free port, a config file written here.

``MosquittoBroker(workdir).start()``; ``stop()``/``start()``/``restart()`` keep the port (and the
persistence file when ``persistence=True``); ``tls=TlsFiles`` serves TLS and asks for client
certificates; ``passwords={"user": "pass"}`` requires them. :func:`make_tls_files` creates a CA, a
server certificate for 127.0.0.1 and a client certificate with ``openssl``; ``other_ca`` makes a CA that
signed nothing, for the wrong-CA test. Every wait is bounded.
"""

from __future__ import annotations

import dataclasses
import os
import signal
import socket
import subprocess
import time
from pathlib import Path
from typing import Dict, List, Optional

import harness

MOSQUITTO = "/usr/sbin/mosquitto"
MOSQUITTO_SUB = "/usr/bin/mosquitto_sub"
MOSQUITTO_PUB = "/usr/bin/mosquitto_pub"
MOSQUITTO_PASSWD = "/usr/bin/mosquitto_passwd"


@dataclasses.dataclass(frozen=True)
class TlsFiles:
    """Paths of the test PKI."""

    ca: Path
    server_cert: Path
    server_key: Path
    client_cert: Path
    client_key: Path
    other_ca: Path


def _openssl(*args: str, cwd: Path) -> None:
    subprocess.run(["openssl", *args], cwd=cwd, check=True, capture_output=True, timeout=30)


def make_tls_files(directory: Path) -> TlsFiles:
    """A CA, a server certificate (SAN IP 127.0.0.1) and a client certificate signed by it, and a second,
    unrelated CA. RSA 2048, valid one day."""
    d = directory
    d.mkdir(parents=True, exist_ok=True)
    for ca in ("ca", "other_ca"):
        _openssl("req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "1", "-subj", f"/CN=micros_rt test {ca}",
                 "-keyout", f"{ca}.key", "-out", f"{ca}.crt", cwd=d)
    (d / "server.ext").write_text("subjectAltName=IP:127.0.0.1,DNS:localhost\n")
    for name, ext in (("server", ["-extfile", "server.ext"]), ("client", [])):
        _openssl("req", "-newkey", "rsa:2048", "-nodes", "-subj", f"/CN=micros_rt test {name}",
                 "-keyout", f"{name}.key", "-out", f"{name}.csr", cwd=d)
        _openssl("x509", "-req", "-in", f"{name}.csr", "-CA", "ca.crt", "-CAkey", "ca.key", "-CAcreateserial",
                 "-days", "1", "-out", f"{name}.crt", *ext, cwd=d)
    return TlsFiles(d / "ca.crt", d / "server.crt", d / "server.key", d / "client.crt", d / "client.key",
                    d / "other_ca.crt")


class MosquittoBroker:
    """One mosquitto process; see the module docstring."""

    def __init__(self, workdir: Path, *, port: Optional[int] = None, persistence: bool = False,
                 tls: Optional[TlsFiles] = None, passwords: Optional[Dict[str, str]] = None,
                 max_packet_size: int = 0) -> None:
        self.workdir = workdir
        self.workdir.mkdir(parents=True, exist_ok=True)
        self.port = port or harness.free_tcp_port()
        self.host = "127.0.0.1"
        self.tls = tls
        self.conf = self.workdir / "mosquitto.conf"
        self.log_path = self.workdir / "mosquitto.log"
        self.proc: Optional["subprocess.Popen[bytes]"] = None
        lines = [f"listener {self.port} 127.0.0.1", "log_dest file " + str(self.log_path), "log_type all",
                 "connection_messages true", "log_timestamp true"]
        if os.geteuid() == 0:
            lines.append("user root")   # else mosquitto drops to 'mosquitto', who cannot read pytest's tmp dirs
        if passwords:
            pw = self.workdir / "passwords"
            pw.write_text("")
            for user, password in passwords.items():
                subprocess.run([MOSQUITTO_PASSWD, "-b", str(pw), user, password], check=True, capture_output=True,
                               timeout=30)
            lines += ["allow_anonymous false", f"password_file {pw}"]
        else:
            lines.append("allow_anonymous true")
        if persistence:
            # saved after every change, so that even a SIGKILLed broker keeps its queued QoS 1/2 messages
            lines += ["persistence true", f"persistence_location {self.workdir}/", "autosave_interval 1",
                      "autosave_on_changes true"]
        if tls is not None:
            lines += [f"cafile {tls.ca}", f"certfile {tls.server_cert}", f"keyfile {tls.server_key}",
                      "require_certificate true"]
        if max_packet_size:
            lines.append(f"max_packet_size {max_packet_size}")
        self.conf.write_text("\n".join(lines) + "\n")

    def start(self, timeout: float = 10.0) -> "MosquittoBroker":
        """Start and wait (bounded) until the port accepts connections."""
        self.proc = subprocess.Popen([MOSQUITTO, "-c", str(self.conf)], stdin=subprocess.DEVNULL,
                                     stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                err = self.proc.stderr.read().decode(errors="replace") if self.proc.stderr else ""
                raise AssertionError(f"mosquitto exited with {self.proc.returncode}: {err}\n{self.log_tail()}")
            try:
                with socket.create_connection((self.host, self.port), timeout=0.5):
                    return self
            except OSError:
                time.sleep(0.05)
        raise AssertionError(f"mosquitto did not listen on {self.port} within {timeout} s\n{self.log_tail()}")

    def stop(self, *, kill: bool = False, timeout: float = 10.0) -> None:
        """SIGTERM (mosquitto saves its persistence file) or SIGKILL; bounded; harmless when stopped."""
        if self.proc is None:
            return
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGKILL if kill else signal.SIGTERM)
            try:
                self.proc.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=timeout)
        if self.proc.stderr is not None:
            self.proc.stderr.close()
        self.proc = None

    def restart(self) -> "MosquittoBroker":
        """Stop and start on the same port."""
        self.stop()
        return self.start()

    def log_tail(self, n: int = 30) -> str:
        try:
            return "\n".join(self.log_path.read_text(errors="replace").splitlines()[-n:])
        except OSError:
            return "(no mosquitto log)"

    def log(self) -> str:
        try:
            return self.log_path.read_text(errors="replace")
        except OSError:
            return ""

    def client_args(self) -> List[str]:
        """``-h -p`` (and TLS options) for mosquitto_sub/mosquitto_pub."""
        args = ["-h", self.host, "-p", str(self.port)]
        if self.tls is not None:
            args += ["--cafile", str(self.tls.ca), "--cert", str(self.tls.client_cert), "--key",
                     str(self.tls.client_key)]
        return args

    def pub(self, topic: str, message: str, *, qos: int = 0, retain: bool = False, timeout: float = 15.0) -> None:
        """mosquitto_pub once (raises on failure)."""
        argv = [MOSQUITTO_PUB, *self.client_args(), "-t", topic, "-m", message, "-q", str(qos)]
        if retain:
            argv.append("-r")
        subprocess.run(argv, check=True, capture_output=True, timeout=timeout)

    def sub_argv(self, topic: str, *, count: int, timeout: float, extra: Optional[List[str]] = None) -> List[str]:
        """A mosquitto_sub command line that prints ``count`` messages then exits (``-W timeout``)."""
        return [MOSQUITTO_SUB, *self.client_args(), "-t", topic, "-C", str(count), "-W", str(int(timeout)),
                *(extra or [])]

    def __enter__(self) -> "MosquittoBroker":
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()


def write_params(path: Path, params: Dict[str, object]) -> Path:
    """An mqtt_client params file (YAML)."""
    import yaml

    path.write_text(yaml.safe_dump(params, sort_keys=False))
    return path


def bridge_argv(params: Path, *, name: str = "mqtt_client", counters: float = 0.5) -> List[str]:
    """``python -m micros_rt.bridges.mqtt`` (the bridge) with the project's venv, printing its counters."""
    return [harness.MICROS_RT_PYTHON, "-m", "micros_rt.bridges.mqtt", "--params", str(params), "--name", name,
            "--print-counters", str(counters)]


def last_counters(peer: "harness.Peer") -> Dict[str, object]:
    """The newest ``counters`` event a bridge printed ({} before the first)."""
    events = peer.events("counters")
    return events[-1] if events else {}
