"""ctypes structures against the one layout table (tests/data/abi_layout.json),
and the table against the header's field lists."""
import ctypes

import header
from cdm import _native


def test_table_covers_every_struct_of_the_header():
    assert set(header.struct_fields()) == set(header.layout())
    assert set(_native.STRUCTS) == set(header.layout())


def test_table_lists_every_field_of_the_header():
    fields = header.struct_fields()
    assert fields["cdm_device_info"][-4:] == ["report_rate_hz", "hall_closed", "hall_open", "grip_open_rad"]
    for name, entry in header.layout().items():
        assert fields[name] == sorted(entry["fields"], key=entry["fields"].get), name


def test_ctypes_sizes_and_offsets():
    for name, entry in header.layout().items():
        cls = _native.STRUCTS[name]
        assert ctypes.sizeof(cls) == entry["size"], name
        assert [f[0] for f in cls._fields_] == sorted(entry["fields"], key=entry["fields"].get), name
        for field, offset in entry["fields"].items():
            assert getattr(cls, field).offset == offset, "%s.%s" % (name, field)


def test_struct_size_is_set():
    for cls in _native.STRUCTS.values():
        assert cls().struct_size == ctypes.sizeof(cls)
