"""The on-disk cache of Cyclone's XTypes type data (micros_rt.transports.dds.typecache): the bytes it hands to
Cyclone are exactly what cyclonedds builds, a damaged file is never used, and it can be turned off."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Iterator

import pytest

from micros_rt.transports.dds import typecache
from micros_rt.transports.dds.typecache import _pack, _unpack, cache_dir


@pytest.fixture
def tmp_cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    monkeypatch.setenv("MICROS_RT_TYPE_CACHE", str(tmp_path))
    yield tmp_path


def _fresh_bytes(idl_class: Any) -> tuple[bytes, bytes]:
    from cyclonedds.idl._support import Endianness
    from cyclonedds.idl._xt_builder import XTBuilder

    info, mapping = XTBuilder.process_type(idl_class)
    return (info.serialize(endianness=Endianness.Little, use_version_2=True)[4:],
            mapping.serialize(endianness=Endianness.Little, use_version_2=True)[4:])


def test_cache_dir_follows_the_environment(tmp_path: Path) -> None:
    assert cache_dir({"MICROS_RT_TYPE_CACHE": "0"}) is None
    assert cache_dir({"MICROS_RT_TYPE_CACHE": "off"}) is None
    assert cache_dir({"MICROS_RT_TYPE_CACHE": str(tmp_path)}) == tmp_path
    assert cache_dir({"XDG_CACHE_HOME": "/x"}) == Path("/x/micros_rt/xtypes")
    assert cache_dir({"HOME": "/home/r"}) == Path("/home/r/.cache/micros_rt/xtypes")


def test_damaged_files_are_refused() -> None:
    blob = _pack(b"info-bytes", b"map")
    assert _unpack(blob) == (b"info-bytes", b"map")
    assert _unpack(blob[:-1]) is None                       # truncated
    assert _unpack(blob[:-1] + bytes([blob[-1] ^ 1])) is None  # a flipped bit
    assert _unpack(b"garbage") is None
    assert _unpack(b"") is None


def test_keys_differ_by_type_and_definition() -> None:
    from sensor_msgs.msg import Image, LaserScan
    from std_msgs.msg import Header, String

    from micros_rt.transports.dds.types import dds_type_for

    keys = {dds_type_for(c).idl_class.__micros_rt_xtypes_key__ for c in (Image, LaserScan, Header, String)}
    assert len(keys) == 4 and all(len(k) == 64 for k in keys)


@pytest.mark.parametrize("type_name", ["std_msgs/String", "sensor_msgs/Image", "sensor_msgs/PointCloud2",
                                       "geometry_msgs/PoseStamped"])
def test_cached_bytes_are_what_cyclonedds_builds(tmp_cache: Path, type_name: str) -> None:
    # a Topic made through the participant stores the type data; the file holds byte for byte what
    # cyclonedds builds from scratch, so a cached start announces the same type as an uncached one
    import roslib.message

    from micros_rt.transports.dds.participant import get_participant
    from micros_rt.transports.dds.types import dds_type_for

    idl = dds_type_for(roslib.message.get_message_class(type_name)).idl_class
    participant = get_participant()
    assert participant is not None
    name = f"rt/micros_rt_typecache_{type_name.replace('/', '_')}"
    participant.topic(name, idl)
    participant.release_topic(name)
    files = {p.name for p in tmp_cache.iterdir()}
    assert f"{idl.__micros_rt_xtypes_key__}.bin" in files
    stored = _unpack((tmp_cache / f"{idl.__micros_rt_xtypes_key__}.bin").read_bytes())
    assert stored == _fresh_bytes(idl)


def test_loaded_type_data_builds_its_objects_when_asked(tmp_cache: Path) -> None:
    # two identical classes: the second gets the first's bytes from the cache; its TypeInformation is
    # built on first use and equals the first's
    from cyclonedds.idl import make_idl_struct
    from cyclonedds.idl import types as t

    def make() -> Any:
        cls = make_idl_struct("micros_rt_test_Cached", "micros_rt_test::Cached", {"a": t.int32, "b": str})
        setattr(cls, "__micros_rt_xtypes_key__", "k" * 64)
        return cls

    first, second = make(), make()
    first.__idl__.fill_type_data()
    typecache.save_type_data(first)
    assert typecache.load_type_data(second) is True
    assert second.__idl__._xt_bytedata == first.__idl__._xt_bytedata
    assert second.__idl__.get_type_info().complete == first.__idl__.get_type_info().complete
    typecache.forget_type_data(second)  # Cyclone refused them: gone from memory and disk
    assert not (tmp_cache / ("k" * 64 + ".bin")).exists()
