#!/usr/bin/env python3
"""Checks udev/70-cdm.rules: udev syntax (key, operator, quoted value), and the
content the project relies on: a hidraw rule for the VID/PID of
src/device/protocol.h with TAG+="uaccess", NO rule granting the raw USB node
(libcdm opens only hidraw), no world-writable MODE, and a file number
below 73 (systemd's seat rules). Runs `udevadm verify` as well when
this udevadm has it (systemd >= 253).

usage: check_udev_rules.py RULES_FILE [PROTOCOL_H]
Exit status 0 when the file passes; each problem is printed as FILE:LINE: text.
"""
import os
import re
import shutil
import subprocess
import sys

MATCH_KEYS = {"ACTION", "DEVPATH", "KERNEL", "KERNELS", "NAME", "SYMLINK", "SUBSYSTEM", "SUBSYSTEMS",
              "DRIVER", "DRIVERS", "ATTR", "ATTRS", "SYSCTL", "ENV", "CONST", "TAG", "TAGS", "TEST",
              "PROGRAM", "RESULT"}
ASSIGN_KEYS = {"NAME", "SYMLINK", "OWNER", "GROUP", "MODE", "SECLABEL", "ATTR", "SYSCTL", "ENV", "TAG",
               "RUN", "LABEL", "GOTO", "IMPORT", "OPTIONS"}
KEYS_WITH_ATTR = {"ATTR", "ATTRS", "SYSCTL", "ENV", "CONST", "TEST", "SECLABEL", "RUN", "IMPORT"}
TOKEN = re.compile(r'\s*([A-Z]+)(?:\{([^}]*)\})?\s*(==|!=|\+=|-=|:=|=)\s*"((?:[^"\\]|\\.)*)"\s*(,|$)')


def parse(path):
    """[(line number, [(key, attr, op, value), ...])]; raises ValueError naming file:line."""
    rules = []
    with open(path) as f:
        lines = f.read().split("\n")
    i = 0
    while i < len(lines):
        n = i + 1
        line = lines[i]
        while line.endswith("\\") and i + 1 < len(lines):  # continuation lines
            i += 1
            line = line[:-1] + lines[i]
        i += 1
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        pos, tokens = 0, []
        while pos < len(line):
            m = TOKEN.match(line, pos)
            if not m:
                raise ValueError("%s:%d: column %d: expected KEY[{attr}]OP\"value\": %r"
                                 % (path, n, pos + 1, line[pos:pos + 40]))
            key, attr, op, value, _ = m.groups()
            if key not in MATCH_KEYS | ASSIGN_KEYS:
                raise ValueError("%s:%d: unknown key %s" % (path, n, key))
            if (attr is not None) != (key in KEYS_WITH_ATTR) and key not in ("RUN", "IMPORT", "SECLABEL"):
                raise ValueError("%s:%d: %s %s an {attribute}" % (path, n, key,
                                                                 "takes" if key in KEYS_WITH_ATTR else "takes no"))
            if op in ("==", "!=") and key not in MATCH_KEYS:
                raise ValueError("%s:%d: %s cannot be matched with %s" % (path, n, key, op))
            if op not in ("==", "!=") and key not in ASSIGN_KEYS:
                raise ValueError("%s:%d: %s cannot be assigned with %s" % (path, n, key, op))
            tokens.append((key, attr, op, value))
            pos = m.end()
        rules.append((n, tokens))
    return rules


def ids_from_protocol(path):
    with open(path) as f:
        src = f.read()
    vid = re.search(r"kVendorId\s*=\s*0x([0-9A-Fa-f]{4})", src)
    pid = re.search(r"kProductId\s*=\s*0x([0-9A-Fa-f]{4})", src)
    if not vid or not pid:
        raise ValueError("%s: kVendorId/kProductId not found" % path)
    return vid.group(1).lower(), pid.group(1).lower()


def check(path, vid, pid):
    problems = []
    name = os.path.basename(path)
    m = re.match(r"(\d+)-", name)
    if not m or int(m.group(1)) >= 73:
        problems.append("%s: the file number must sort before 73-seat-late.rules, got %r" % (path, name))
    try:
        rules = parse(path)
    except ValueError as e:
        return [str(e)]
    found = {"hidraw": False}
    for n, tokens in rules:
        match = {(k, a): v for k, a, op, v in tokens if op == "=="}
        for k, a, op, v in tokens:
            if k == "MODE" and re.fullmatch(r"0?[0-7]{3}", v) and int(v, 8) & 0o002:
                problems.append("%s:%d: MODE=\"%s\" is world-writable; use TAG+=\"uaccess\"" % (path, n, v))
            if k == "TAG" and op == "=" and v == "uaccess":
                problems.append("%s:%d: TAG=\"uaccess\" replaces the other tags; use TAG+=" % (path, n))
        subsystem = match.get(("SUBSYSTEM", None))
        grants = any(k in ("TAG", "MODE", "GROUP", "OWNER") and op != "==" for k, a, op, v in tokens)
        if subsystem in ("usb", "usb_device") and grants:
            problems.append("%s:%d: grants the raw USB node; libcdm needs only the hidraw node" % (path, n))
            continue
        if subsystem not in found:
            continue
        key = "ATTRS" if subsystem == "hidraw" else "ATTR"  # hidraw nodes: the IDs sit on a parent
        if match.get((key, "idVendor")) != vid or match.get((key, "idProduct")) != pid:
            problems.append("%s:%d: %s rule must match %s{idVendor}==\"%s\" and %s{idProduct}==\"%s\""
                            % (path, n, subsystem, key, vid, key, pid))
            continue
        if ("TAG", None, "+=", "uaccess") not in tokens:
            problems.append("%s:%d: %s rule lacks TAG+=\"uaccess\"" % (path, n, subsystem))
            continue
        found[subsystem] = True
    for subsystem, ok in found.items():
        if not ok:
            problems.append("%s: no %s rule for %s:%s with TAG+=\"uaccess\"" % (path, subsystem, vid, pid))
    return problems


def main(argv):
    if len(argv) < 2:
        print(__doc__, file=sys.stderr)
        return 2
    path = argv[1]
    root = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
    protocol = argv[2] if len(argv) > 2 else os.path.join(root, "src", "device", "protocol.h")
    vid, pid = ids_from_protocol(protocol)
    problems = check(path, vid, pid)
    udevadm = shutil.which("udevadm")
    if udevadm:
        has_verify = subprocess.run([udevadm, "verify", "--help"], capture_output=True).returncode == 0
        if has_verify:
            r = subprocess.run([udevadm, "verify", path], capture_output=True, text=True)
            if r.returncode != 0:
                problems.append("udevadm verify: " + (r.stdout + r.stderr).strip())
        else:
            print("note: %s has no `verify` (systemd < 253): syntax checked by this script only" % udevadm)
    else:
        print("note: no udevadm: syntax checked by this script only")
    for p in problems:
        print(p)
    print("%s: %s" % (path, "OK" if not problems else "%d problem(s)" % len(problems)))
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
