"""A verify run as JUnit XML and as SARIF 2.1.0, the formats CI systems and code-scanning pages read.

Both take the run's projects (mpgspec.pipeline.results.ProjectResult: path, name, status, report, errors).

JUnit: a test suite per project, a test case per assertion, per Definition 1 check (assumption) and per
cross-checked run; a project that could not be verified is one test case with an error. Warnings (an
assumption that warns, a cross-check disagreement) are failures only under --strict, as in the exit
code; otherwise the case passes and says WARN in its output.

SARIF: one run of the tool `mpgspec`, a result per failed assertion, per assumption check that is not
passed, per cross-check disagreement and per error of a project, each at the spec's file:line where it
is known. Rules are the error codes (`mpgspec explain`) and the kinds of finding.
"""
from __future__ import annotations

import os
import re
import socket
import time
from pathlib import Path
from types import SimpleNamespace
from urllib.parse import quote
from xml.etree import ElementTree as ET

from .. import __version__
from ..codes import CODES
from .findings import disagreements, nominal_only_path, path_text

SARIF_SCHEMA = "https://json.schemastore.org/sarif-2.1.0.json"
LEVEL = {"fail": "error", "error": "error", "warn": "warning", "info": "note"}
KINDS = {
    "assertion": "an assertion of the project spec does not hold",
    "assumption": "a Definition 1 check (a primitive's assumptions) failed or warns",
    "crosscheck": "a run replayed in an independent simulator reached another verdict than mpgspec's",
    "robust": "the graph run takes edges that did not withstand the project's uncertainty (nominal only)",
}


CHECK_PARTS = ("plan_execute_s", "crosscheck_s", "robust_s", "assumptions_s")
"""The check stage's parts: they run side by side, each timed from the stage's start (checks_s is the whole)."""


def project_seconds(t: dict) -> float:
    """A project's wall time from its report's timing: the phases one after the other, the check
    stage counted once (checks_s, when the report has it, instead of its overlapping parts)."""
    skip = CHECK_PARTS if "checks_s" in t else ()
    return float(sum(v for k, v in t.items() if k.endswith("_s") and not k.endswith("per_s") and k not in skip
                     and isinstance(v, (int, float))))


def _seconds(report: dict | None) -> float:
    return project_seconds((report or {}).get("timing") or {})


def _time(s: float) -> str:
    """Seconds as JUnit's SUREFIRE_TIME pattern allows: digits, a point, at most three decimals."""
    return f"{max(s, 0.0):.3f}"


NOT_XML = re.compile("[\x00-\x08\x0b\x0c\x0e-\x1f\ud800-\udfff\ufffe\uffff]")
"""Characters XML 1.0 cannot hold (a spec or a message could contain them)."""


def _xml(text) -> str:
    return NOT_XML.sub("\ufffd", str(text))


def _where(loc: dict | None) -> str:
    return f" ({loc['file']}:{loc['line']})" if loc and loc.get("line") else ""


def _cases(p, strict: bool) -> list[tuple[str, str, str, str | None, str, str]]:
    """(kind, classname, name, outcome, message, output) for each test case of a project; outcome None
    (passed), 'failure' or 'error'; kind names the finding (assertion, assumption, crosscheck, robust)."""
    name = p.name or str(p.path)
    if p.report is None:
        msg = "; ".join(e.get("message", "") for e in p.errors) or "the project could not be verified"
        code = next((e.get("code") for e in p.errors if e.get("code")), "MPG000")
        return [("verify", name, "verify", "error", f"{code}: {msg}", "\n".join(e.get("text", "") for e in p.errors))]
    r = p.report
    out = []
    for a in r.get("assertions", []):
        bad = a["status"] in ("fail", "error")
        out.append(("assertion", f"{name}.assertions", a["description"],
                    ("failure" if a["status"] == "fail" else "error") if bad else None, a.get("message", ""),
                    f"{a['status'].upper()} {a.get('message', '')}{_where(a.get('location'))}"))
    for c in r.get("assumptions", []):
        st = c["status"]
        outcome = "failure" if st in ("fail", "error") or (st == "warn" and strict) else None
        out.append(("assumption", f"{name}.assumptions.{c['primitive']}", c["name"], outcome, c.get("message", ""),
                    f"{st.upper()} {c.get('message', '')}{_where(c.get('location'))}"))
    found = disagreements(r)
    disputed = {d["mode"]: d["text"] for d in found if "variant" not in d}
    for mode in ((r.get("crosscheck") or {}).get("runs") or {}):
        text = disputed.get(mode)
        out.append(("crosscheck", f"{name}.crosscheck", f"{mode} run", "failure" if text and strict else None,
                    text or "", f"WARN {text}" if text else "agrees"))
    varied = {d["variant"]: d["text"] for d in found if "variant" in d}
    for v in ((r.get("crosscheck") or {}).get("variants") or []):
        text = varied.get(str(v.get("name")))
        out.append(("crosscheck", f"{name}.crosscheck", f"graph run with {v.get('name')}",
                    "failure" if text and strict else None, text or "", f"WARN {text}" if text else "agrees"))
    bad = nominal_only_path(r)
    if r.get("robust"):
        out.append(("robust", f"{name}.robust", "graph run's path", "failure" if bad and strict else None,
                    path_text(bad) if bad else "", f"WARN {path_text(bad)}" if bad else "every edge is robust"))
    for e in p.errors:  # e.g. the reports could not be written
        out.append(("verify", name, "write reports", "error", e.get("message", ""), e.get("text", "")))
    return out


def junit(projects: list, strict: bool = False, errors=()) -> str:
    """The run as JUnit XML (the schema Jenkins, GitLab and pytest's junit-10.xsd read); errors: those
    that ended the command before any project was verified (a usage error), as one erroring case."""
    if errors:
        projects = [*projects, SimpleNamespace(path="mpgspec", name="mpgspec", status="error", report=None,
                                               errors=list(errors))]
    root = ET.Element("testsuites", name="mpgspec verify")
    totals = {"tests": 0, "failures": 0, "errors": 0}
    stamp = time.strftime("%Y-%m-%dT%H:%M:%S", time.localtime())
    total_s = 0.0
    for p in projects:
        cases = _cases(p, strict)
        s = _seconds(p.report)
        total_s += s
        counts = {"tests": len(cases), "failures": sum(c[3] == "failure" for c in cases),
                  "errors": sum(c[3] == "error" for c in cases)}
        suite = ET.SubElement(root, "testsuite", name=_xml(p.name or p.path), file=_xml(p.path), skipped="0",
                              time=_time(s), timestamp=stamp, hostname=socket.gethostname(),
                              **{k: str(v) for k, v in counts.items()})
        props = ET.SubElement(suite, "properties")
        for k, v in _properties(p).items():
            ET.SubElement(props, "property", name=k, value=_xml(v))
        for kind, classname, name, outcome, message, output in cases:
            case = ET.SubElement(suite, "testcase", classname=_xml(classname), name=_xml(name), time="0.000")
            if outcome:
                ET.SubElement(case, outcome, message=_xml(message[:2000]), type=kind).text = _xml(output)
            elif output:
                ET.SubElement(case, "system-out").text = _xml(output)
        for k in totals:
            totals[k] += counts[k]
    root.set("time", _time(total_s))
    for k, v in totals.items():
        root.set(k, str(v))
    ET.indent(root)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def _properties(p) -> dict:
    r = p.report or {}
    out = {"mpgspec": __version__, "status": p.status}
    if r:
        v = r.get("verdicts") or {}
        out.update({"primitives": len(r.get("primitives", [])), "edges": len(r.get("edges", [])),
                    "oracle_calls": (r.get("timing") or {}).get("oracle_calls", 0),
                    "inconclusive": v.get("inconclusive", 0)})
    return out


def _uri(path: str) -> str:
    """A file as a SARIF artifact URI: relative to the working folder when below it (how code
    scanning matches files of the repository), else absolute as a file: URI."""
    try:
        rel = os.path.relpath(path)
    except ValueError:
        rel = ".."
    if not rel.startswith(".."):
        return quote(rel.replace(os.sep, "/"))
    return Path(os.path.abspath(path)).as_uri()


def _result(rule: str, level: str, text: str, loc: dict | None, fallback) -> dict:
    physical = {"artifactLocation": {"uri": _uri(str((loc or {}).get("file") or fallback))}}
    if loc and loc.get("line"):
        physical["region"] = {"startLine": int(loc["line"])}
        if loc.get("column"):
            physical["region"]["startColumn"] = int(loc["column"])
    return {"ruleId": rule, "level": level, "message": {"text": text},
            "locations": [{"physicalLocation": physical}]}


def sarif(projects: list, strict: bool = False, exit_code: int = 0, errors=()) -> dict:
    """The run as a SARIF 2.1.0 log (GitHub code scanning, VS Code's SARIF viewer); errors: those that
    ended the command before any project was verified."""
    results = [_result(e.get("code") or "MPG000", "error", e.get("message", ""), e, e.get("file") or ".")
               for e in errors]
    for p in projects:
        name = p.name or str(p.path)
        project_file = p.path if str(p.path).endswith((".yaml", ".yml")) else os.path.join(str(p.path), "project.yaml")
        for e in p.errors:
            results.append(_result(e.get("code") or "MPG000", "error", e.get("message", ""), e, project_file))
        r = p.report
        if r is None:
            continue
        for a in r.get("assertions", []):
            if a["status"] != "pass":
                results.append(_result("assertion", LEVEL.get(a["status"], "error"),
                                       f"{name}: {a['description']}: {a.get('message', '')}", a.get("location"),
                                       project_file))
        for c in r.get("assumptions", []):
            if c["status"] != "pass":
                level = "error" if c["status"] == "warn" and strict else LEVEL.get(c["status"], "error")
                results.append(_result("assumption", level, f"{name}: assumption {c['name']} of {c['primitive']}: "
                                       f"{c.get('message', '')}", c.get("location"), project_file))
        for d in disagreements(r):
            results.append(_result("crosscheck", "error" if strict else "warning",
                                   f"{name}: cross-check of the {d['mode']} run: {d['text']}", None, project_file))
        if (bad := nominal_only_path(r)) is not None:
            results.append(_result("robust", "error" if strict else "warning", f"{name}: {path_text(bad)}", None,
                                   project_file))
    used = {x["ruleId"] for x in results}
    rules = [{"id": k, "shortDescription": {"text": v}} for k, v in KINDS.items()]
    rules += [{"id": k, "name": short, "shortDescription": {"text": short}, "fullDescription": {"text": full},
               "help": {"text": f"{full} (`mpgspec explain {k}`)"}}
              for k, (short, full) in CODES.items() if k in used]
    return {"$schema": SARIF_SCHEMA, "version": "2.1.0", "runs": [{
        "tool": {"driver": {"name": "mpgspec", "version": __version__, "rules": rules}},
        "invocations": [{"executionSuccessful": exit_code in (0, 1), "exitCode": int(exit_code)}],
        "results": results}]}
