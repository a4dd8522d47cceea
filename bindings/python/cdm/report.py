"""Runs the report tool from a source tree: ``python3 bindings/python/cdm/report.py ARGS``,
the same as ``python3 -m cdm.report ARGS``.

The tool is the package ``report/`` beside this file. ``import cdm.report`` and
``-m cdm.report`` always find that package (a package wins over a module of the
same name), so this file is only ever run as a script: the source tree's
entry point. It is not installed.
"""

if __name__ == "__main__":
    import importlib.util
    import os
    import sys

    _here = os.path.dirname(os.path.abspath(__file__))
    # Run as a script, this directory is sys.path[0]: do not let the package's
    # modules (log, errors, ...) shadow others of the same name.
    sys.path[:] = [p for p in sys.path if os.path.abspath(p or ".") != _here]
    # The report package alone, under its own name: not cdm/__init__.py, so that
    # the report runs whatever state the ctypes binding is in.
    _pkg = os.path.join(_here, "report")
    _spec = importlib.util.spec_from_file_location(
        "cdm_report", os.path.join(_pkg, "__init__.py"), submodule_search_locations=[_pkg])
    _m = importlib.util.module_from_spec(_spec)
    sys.modules[_spec.name] = _m
    _spec.loader.exec_module(_m)
    sys.exit(_m.main())
