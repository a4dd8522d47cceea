"""The binding's constants are the header's, both ways."""
import cdm
import header


def test_header_parser_sees_the_enums():
    c = header.constants()
    # If the parser broke, every comparison below would pass on an empty dict.
    assert c["CDM_ERR_INTERNAL"] == -15 and c["CDM_POSE_END_OF_STREAM"] == 16 and c["CDM_BUTTON_MARK"] == 4
    assert len(c) >= 28


def test_every_header_constant_is_in_python_with_its_value():
    for name, value in header.constants().items():
        assert hasattr(cdm, name), "%s is in cdm.h but not in cdm.constants" % name
        assert getattr(cdm, name) == value, "%s: header %d, Python %d" % (name, value, getattr(cdm, name))


def test_every_python_constant_is_in_the_header():
    c = header.constants()
    for name in cdm.constants.__all__:
        if name.startswith("CDM_") and name != "CDM_VERSION_NUMBER":
            assert name in c, "cdm.%s is not in cdm.h" % name


def test_error_count_covers_the_codes():
    assert cdm.CDM_ERROR_COUNT == len(cdm.Error)


def test_library_strerror_knows_every_code(lib):
    unknown = lib.cdm_strerror(-1000)
    for code in cdm.Error:
        assert lib.cdm_strerror(code) != unknown, code.name


def test_loaded_library_version_matches_header():
    assert cdm.version_number() == cdm.CDM_VERSION_NUMBER
    assert cdm.version() == "%d.%d.%d" % (cdm.CDM_VERSION_MAJOR, cdm.CDM_VERSION_MINOR, cdm.CDM_VERSION_PATCH)
