"""Exit codes (0 success, 1 runtime failure, 2 usage error) of every subcommand,
and the messages a user reads: usage, unknown commands, defaults, numbers,
--json, the report started without a shell."""
import json
import os
import re
import subprocess

import pytest

from conftest import cdm

MISSING = "/nonexistent/cdm-test/missing"


def test_no_command_prints_usage():
    r = cdm()
    assert r.returncode == 2
    assert "Usage: cdm" in r.stderr and "Exit status" in r.stderr


@pytest.mark.parametrize("args,name", [(["bogus"], "bogus"), (["calib", "frobnicate"], "frobnicate")])
def test_unknown_command_is_named(args, name):
    r = cdm(*args)
    assert r.returncode == 2
    assert '"%s"' % name in r.stderr and "unknown command" in r.stderr


def test_group_without_subcommand_is_usage():
    r = cdm("calib")
    assert r.returncode == 2 and "diagnose" in r.stderr


# (arguments, expected exit code); None = a runtime failure this command
# cannot be brought to by arguments alone (list and effects read nothing).
CASES = {
    "list": [(["list"], 0), (["list", "--bogus"], 2)],
    "info": [(["info", "sim:"], 0), (["info", "replay:" + MISSING], 1), (["info"], 2)],
    "stream": [(["stream", "sim:", "--seconds", "0.2"], 0), (["stream", "replay:" + MISSING], 1),
               (["stream", "sim:", "--rate", "0.1"], 2)],
    "record": [(["record", "sim:", "{tmp}/r.cdmrec", "--seconds", "0.2"], 0),
               (["record", "replay:" + MISSING, "{tmp}/r2.cdmrec"], 1), (["record", "sim:"], 2)],
    "calib diagnose": [(["calib", "diagnose", "{data}", "--quiet", "--no-candidates"], 0),
                       (["calib", "diagnose", MISSING + ".csv", "--quiet"], 1),
                       (["calib", "diagnose", "{data}", "--jig-tolerance-mm", "abc"], 2)],
    "calib fit": [(["calib", "fit", "{data}", "--effects", "cable_offset", "--out", "{tmp}/c.json", "--quiet"], 0),
                  (["calib", "fit", MISSING + ".csv", "--effects", "cable_offset", "--out", "{tmp}/c2.json"], 1),
                  (["calib", "fit", "{data}", "--out", "{tmp}/c3.json"], 2)],
    "calib simulate": [(["calib", "simulate", "{tmp}/s.csv", "--holes", "3", "--heights", "40", "--samples", "2"], 0),
                       (["calib", "simulate", MISSING + ".csv", "--holes", "3"], 1),
                       (["calib", "simulate", "{tmp}/s2.csv", "--heights", "abc"], 2)],
    "calib effects": [(["calib", "effects"], 0), (["calib", "effects", "extra"], 2)],
}


@pytest.mark.parametrize("command,args,code",
                         [(c, a, k) for c, cases in CASES.items() for a, k in cases],
                         ids=lambda v: v if isinstance(v, str) else None)
def test_exit_code(command, args, code, tmp_path, small_dataset):
    argv = [a.format(tmp=tmp_path, data=small_dataset) for a in args]
    r = cdm(*argv)
    assert r.returncode == code, (argv, r.stdout, r.stderr)
    if code:
        assert r.stderr.strip(), "a failure says why on stderr"
        assert "Traceback" not in r.stderr and "terminate called" not in r.stderr


def test_heights_not_a_number_names_the_option(tmp_path):
    r = cdm("calib", "simulate", str(tmp_path / "x.csv"), "--heights", "abc")
    assert r.returncode == 2
    assert "--heights" in r.stderr and '"abc"' in r.stderr
    assert not (tmp_path / "x.csv").exists()


@pytest.mark.parametrize("args, words", [
    (["calib", "diagnose", "{data}", "--json", ""], "--json: an empty value"),
    (["calib", "simulate", "{tmp}/s.csv", "--heights", ""], "--heights: an empty value"),
    (["calib", "simulate", "{tmp}/s.csv", "--heights", "40,,60"], 'an empty item in "40,,60"'),
])
def test_an_empty_value_is_not_the_default(tmp_path, small_dataset, args, words):
    """An empty value is refused, not taken as the option left out."""
    r = cdm(*[a.format(data=small_dataset, tmp=tmp_path) for a in args])
    assert r.returncode == 2 and words in r.stderr, r.stderr
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("args", [
    ["calib", "plan", "--positions", "3", "--jig-n", "3", "--jig-heights", "50,60", "--out", "{tmp}/p.json",
     "--json", "{tmp}/./p.json"],
    ["calib", "simulate", "{tmp}/x.csv", "--holes", "3", "--heights", "50", "--truth-out", "{tmp}/x.csv"],
    ["calib", "fit", "{data}", "--effects", "cable_gain", "--out", "{tmp}/o.json", "--json", "{tmp}/o.json"],
])
def test_two_outputs_on_one_file_are_refused(tmp_path, small_dataset, args):
    r = cdm(*[a.format(data=small_dataset, tmp=tmp_path) for a in args])
    assert r.returncode == 2 and "are the same file" in r.stderr, r.stderr
    assert not list(tmp_path.iterdir())


def test_file_names_that_are_not_utf8(tmp_path, small_dataset):
    """A dataset named in Latin-1 is read (its name shown with U+FFFD in the
    results); an output that libcdm must be told in JSON is refused, naming
    the option."""
    import shutil
    data = os.fsencode(str(tmp_path)) + b"/caf\xe9.csv"
    shutil.copyfile(small_dataset, data)
    out = str(tmp_path / "cal.json")
    r = cdm("calib", "fit", data, "--effects", "cable_gain", "--out", out, "--json", str(tmp_path / "fit.json"),
            timeout=300, errors="replace")
    assert r.returncode == 0, r.stderr
    assert json.loads((tmp_path / "fit.json").read_text(encoding="utf-8"))["error_mm"]
    assert json.loads((tmp_path / "cal.json").read_text(encoding="utf-8"))["effects"]
    d = tmp_path / "d.json"
    r = cdm("calib", "diagnose", data, "--quiet", "--no-candidates", "--json", str(d), timeout=300, errors="replace")
    assert r.returncode == 0, r.stderr
    assert "caf\ufffd.csv" in d.read_text(encoding="utf-8")
    r = cdm("calib", "fit", str(small_dataset), "--effects", "cable_gain", "--out",
            os.fsencode(str(tmp_path)) + b"/cal\xe9.json")
    assert r.returncode == 2 and "--out" in r.stderr and "not UTF-8" in r.stderr, r.stderr


def test_fit_without_effects_is_usage(tmp_path, small_dataset):
    r = cdm("calib", "fit", str(small_dataset), "--out", str(tmp_path / "c.json"))
    assert r.returncode == 2 and "--effects" in r.stderr
    assert not (tmp_path / "c.json").exists()


def test_numbers_as_a_person_writes_them():
    r = cdm("stream", "sim:", "--rate", "5000")
    assert r.returncode == 2
    assert "[0.5, 1000]" in r.stderr
    assert not re.search(r"\d\.\d{6}", r.stderr) and "18446744073709551615" not in r.stderr


@pytest.mark.parametrize("sub", [[], ["list"], ["info"], ["stream"], ["record"], ["calib"], ["calib", "diagnose"],
                                 ["calib", "fit"], ["calib", "simulate"], ["calib", "effects"]])
def test_help_shows_exit_codes(sub):
    r = cdm(*sub, "--help")
    assert r.returncode == 0
    assert "0 success, 1 runtime failure" in r.stdout and "2 usage error" in r.stdout


def test_help_shows_defaults():
    sim = cdm("calib", "simulate", "--help").stdout
    for default in ["--noise-mm FLOAT:in [0, 100]=0.05", "--holes INT:in [1, 1000]=25",
                    "--seed UINT:in [0, 9007199254740991]=1",
                    "default: 30,40,50,60,70"]:
        assert default in sim
    assert "comma-separated list" in sim.split("--effects", 1)[1].split("\n")[0]
    assert "--rate FLOAT:in [0.5, 1000]=10" in cdm("stream", "--help").stdout
    diag = cdm("calib", "diagnose", "--help").stdout
    assert "default: the nominal" in diag and "comma-separated list" in diag and "PYTHON" in diag


def test_diagnose_without_device_uses_nominal(small_dataset):
    r = cdm("calib", "diagnose", str(small_dataset), "--quiet", "--no-candidates")
    assert r.returncode == 0, r.stderr
    assert "no --device: using the nominal geometry (a 150 mm, b 150 mm, m 30 mm)" in r.stderr


@pytest.mark.parametrize("args", [["list", "--json"], ["info", "sim:", "--json"], ["calib", "effects", "--json"]])
def test_json_parses(args):
    r = cdm(*args)
    assert r.returncode == 0, r.stderr
    v = json.loads(r.stdout)
    if args[0] == "info":
        assert v["transport"] == "sim" and v["a_mm"] > 0
    if args[-2:] == ["effects", "--json"]:
        names = [e["name"] for e in v]
        assert "cable_offset" in names
        assert all(p["unit"] and p["lower"] < p["upper"] for e in v for p in e["parameters"])


def test_stream_json_is_one_object_per_line():
    r = cdm("stream", "sim:", "--seconds", "0.5", "--rate", "20", "--json", "--truth")
    assert r.returncode == 0, r.stderr
    lines = [json.loads(line) for line in r.stdout.splitlines()]
    poses = [x for x in lines if "sequence" in x]
    assert len(poses) >= 3 and lines[-1]["summary"] is True and lines[-1]["reports"] > 0
    # The truth is on: the simulated driver's error is reported per line.
    assert all(len(p["error_mm"]) == 3 for p in poses)


def test_report_path_with_quote_and_space(tmp_path, small_dataset):
    out = tmp_path / "it's a dir" / "rep"
    os.makedirs(out.parent)
    r = cdm("calib", "diagnose", str(small_dataset), "--quiet", "--no-candidates", "--report", str(out), timeout=300)
    assert r.returncode == 0, r.stderr
    assert (out / "index.html").is_file()


def test_report_paths_starting_with_a_dash(tmp_path, small_dataset):
    """Relative paths that look like options ("-data.csv", "--report -rep"):
    the dataset after `--`, and each path handed to the report's child, reach
    their files, never an option parser."""
    import shutil
    shutil.copy2(small_dataset, tmp_path / "-data.csv")
    r = cdm("calib", "diagnose", "--quiet", "--no-candidates", "--report", "-rep", "--", "-data.csv",
            timeout=300, cwd=str(tmp_path))
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "-rep" / "index.html").is_file()


def test_report_refuses_a_directory_it_does_not_own(tmp_path, small_dataset):
    """`--report .` in the user's working directory: refused before anything
    is written there (not even the diagnosis JSON), the user's files kept."""
    out = tmp_path / "work"
    out.mkdir()
    (out / "residual_map_h40.png").write_bytes(b"the user's own")
    (out / "diagnosis.json").write_text("the user's own")
    r = cdm("calib", "diagnose", str(small_dataset), "--quiet", "--no-candidates", "--report", str(out))
    assert r.returncode == 2 and "holds no report" in r.stderr, r.stderr
    assert sorted(p.name for p in out.iterdir()) == ["diagnosis.json", "residual_map_h40.png"]
    assert (out / "diagnosis.json").read_text() == "the user's own"


def test_report_lists_its_json_and_keeps_the_users(tmp_path, small_dataset):
    """The JSON a report is drawn from is in its marker; a file of the user's
    by that name in a report's directory is never written over, and an
    earlier diagnosis compared with is never replaced: both refused before
    the work."""
    out = tmp_path / "rep"
    r = cdm("calib", "diagnose", str(small_dataset), "--quiet", "--no-candidates", "--report", str(out), timeout=300)
    assert r.returncode == 0, r.stderr
    assert "diagnosis.json" in (out / ".cdm-report").read_text().split()
    r = cdm("calib", "diagnose", str(small_dataset), "--quiet", "--no-candidates", "--report", str(out),
            "--before", str(out / "diagnosis.json"))
    assert r.returncode == 2 and "which the report would replace" in r.stderr, r.stderr
    assert "Recommended model" not in r.stdout  # refused before the work
    (out / "check.json").write_text("the user's own")
    cal = tmp_path / "cal.json"
    assert cdm("calib", "fit", str(small_dataset), "--effects", "cable_gain", "--out", str(cal),
               timeout=300).returncode == 0
    r = cdm("calib", "check", str(small_dataset), "--calibration", str(cal), "--report", str(out))
    assert r.returncode == 2 and ".cdm-report does not list it" in r.stderr, r.stderr
    assert (out / "check.json").read_text() == "the user's own"
    # A result of cdm's own by that name is what a report wrote there before
    # its marker listed the JSON: replaced.
    (out / "check.json").write_text(json.dumps({"tool": "cdm calib check"}))
    r = cdm("calib", "check", str(small_dataset), "--calibration", str(cal), "--report", str(out), "--quiet",
            timeout=300)
    assert r.returncode == 0, r.stderr
    assert "check.json" in (out / ".cdm-report").read_text().split()
    assert "diagnosis.json" not in (out / ".cdm-report").read_text().split()


def test_report_says_what_to_install(tmp_path, small_dataset):
    env = dict(os.environ, PYTHON="/bin/false")
    r = cdm("calib", "diagnose", str(small_dataset), "--quiet", "--no-candidates", "--report",
            str(tmp_path / "rep"), env=env)
    assert r.returncode == 1
    assert "pip install" in r.stderr and "PYTHON" in r.stderr


def test_report_found_in_an_installed_tree(tmp_path, small_dataset):
    """The layout the .deb installs (bin/cdm, lib/python3/dist-packages/cdm), with
    no cdm-pythonpath beside the executable and cdm not importable otherwise:
    cdm finds the package from its own path, not from the build machine's."""
    import shutil
    src = os.environ["CDM_SOURCE_DIR"]
    prefix = tmp_path / "prefix"
    (prefix / "bin").mkdir(parents=True)
    shutil.copy2(os.environ["CDM_CLI"], prefix / "bin" / "cdm")
    shutil.copytree(os.path.join(src, "bindings", "python", "cdm"), prefix / "lib" / "python3" / "dist-packages" / "cdm",
                    ignore=shutil.ignore_patterns("__pycache__", "report.py"))
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHON")}
    out = tmp_path / "rep"
    r = subprocess.run([str(prefix / "bin" / "cdm"), "calib", "diagnose", str(small_dataset), "--quiet",
                        "--no-candidates", "--report", str(out)], capture_output=True, text=True, env=env,
                       timeout=300, cwd=str(tmp_path))
    assert r.returncode == 0, r.stderr
    assert (out / "index.html").is_file()
