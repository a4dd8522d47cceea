"""A small reader of include/cdm/cdm.h for the binding tests: the header is the
one source of truth that the Python (and C#) mirrors are checked against."""
import json
import os
import re

ROOT = os.environ.get("CDM_SOURCE_DIR") or os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
HEADER = os.path.join(ROOT, "include", "cdm", "cdm.h")
LAYOUT = os.path.join(ROOT, "tests", "data", "abi_layout.json")


def text():
    with open(HEADER) as f:
        src = f.read()
    src = re.sub(r"/\*.*?\*/", " ", src, flags=re.S)
    return re.sub(r"//[^\n]*", " ", src)


def _value(expr):
    expr = expr.strip().replace("u", "").replace("U", "")
    m = re.fullmatch(r"\(?\s*(-?\d+)\s*<<\s*(\d+)\s*\)?", expr)
    if m:
        return int(m.group(1)) << int(m.group(2))
    return int(expr)


def constants():
    """{name: value} of every enumerator and CDM_VERSION_{MAJOR,MINOR,PATCH}."""
    src = text()
    out = {}
    for body in re.findall(r"enum\s+\w+\s*\{(.*?)\}", src, flags=re.S):
        for name, expr in re.findall(r"\b(CDM_\w+)\s*=\s*([^,]+)", body):
            out[name] = _value(expr)
    for name, val in re.findall(r"#define\s+(CDM_VERSION_(?:MAJOR|MINOR|PATCH))\s+(\d+)", src):
        out[name] = int(val)
    return out


def functions():
    """{name: (return type, [parameter types])} of every CDM_API function."""
    src = " ".join(text().split())
    out = {}
    for ret, name, params in re.findall(r"CDM_API\s+([\w\s\*]+?)\s*\b(cdm_\w+)\s*\(([^)]*)\)\s*;", src):
        types = []
        for p in params.split(","):
            p = p.strip()
            if p in ("", "void"):
                continue
            array = "[" in p
            p = re.sub(r"\[.*?\]", "", p).strip()
            # Drop the parameter's name: the last identifier, unless the type is one word.
            m = re.fullmatch(r"(.*?[\s\*])(\w+)", p)
            t = m.group(1) if m and m.group(1).strip() not in ("", "const") else p
            t = " ".join(t.replace("*", " * ").split())
            types.append(t + (" *" if array else ""))
        out[name] = (" ".join(ret.replace("*", " * ").split()), types)
    return out


def struct_fields():
    """{struct name: [field names]} of every public typedef'd struct with a body."""
    src = text()
    out = {}
    for name, body in re.findall(r"typedef\s+struct\s+(cdm_\w+)\s*\{(.*?)\}\s*\1\s*;", src, flags=re.S):
        fields = []
        for decl in body.split(";"):
            decl = " ".join(decl.split())
            if not decl:
                continue
            # "double a_mm, b_mm, m_mm" declares three; "const char *const *param_names" one.
            head, _, rest = decl.partition(",")
            names = [re.sub(r"\[.*?\]", "", head).replace("*", " ").split()[-1]]
            names += [re.sub(r"\[.*?\]", "", r).replace("*", " ").strip() for r in rest.split(",") if rest]
            fields += names
        out[name] = fields
    return out


def layout():
    with open(LAYOUT) as f:
        return json.load(f)["structs"]
