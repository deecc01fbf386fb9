"""A suite run as JUnit XML, the format CI servers read: a test case per case and device."""

from __future__ import annotations

from pathlib import Path


def junit_xml(suite: str, outcomes) -> bytes:
    """JUnit XML as CI servers read it: a test case per case and device; `biased` where unexpected is a
    failure, a case that could not run an error, a missing device a skip; inconclusive is a failure too (its
    message says so), since the case did not pass."""
    import xml.etree.ElementTree as ET

    counts = {s: sum(o.status == s for o in outcomes) for s in ("failed", "inconclusive", "error", "skipped")}
    root = ET.Element("testsuites")
    group = ET.SubElement(
        root,
        "testsuite",
        name=suite,
        tests=str(len(outcomes)),
        failures=str(counts["failed"] + counts["inconclusive"]),
        errors=str(counts["error"]),
        skipped=str(counts["skipped"]),
        time=f"{sum(o.seconds for o in outcomes):.3f}",
    )
    for o in outcomes:
        case = ET.SubElement(group, "testcase", classname=f"{suite}.{o.device}", name=o.case.name,
                             time=f"{o.seconds:.3f}")  # fmt: skip
        if o.status in ("failed", "inconclusive"):
            ET.SubElement(case, "failure", message=f"{o.verdict}: {o.message}", type=o.status)
        elif o.status == "error":
            ET.SubElement(case, "error", message=o.message, type="error")
        elif o.status == "skipped":
            ET.SubElement(case, "skipped", message=o.message)
        out = ET.SubElement(case, "system-out")
        out.text = o.message + (f"\nreport: {Path(o.folder) / 'report.html'}" if o.folder else "")
    ET.indent(root)
    return ET.tostring(root, encoding="utf-8", xml_declaration=True)
