"""A suite run as JUnit XML, the format CI servers read: a test case per case and device."""

from __future__ import annotations

import re
from pathlib import Path

from ..jobs.protocol import CaseStatus
from .statuses import STATUSES

#: Characters XML 1.0 does not allow (C0 controls but tab, newline and carriage return): a renderer's message
#: may hold them, and one of them makes the whole file unreadable to a CI server.
_NOT_XML = re.compile(r"[\x00-\x08\x0b\x0c\x0e-\x1f\x7f\ud800-\udfff\ufffe\uffff]")


def xml_text(text: str) -> str:
    """`text` with the characters XML can't hold shown as U+FFFD."""
    return _NOT_XML.sub("\ufffd", str(text))


def junit_xml(suite: str, outcomes) -> bytes:
    """JUnit XML as CI servers read it: a test case per case and device; `biased` where unexpected is a
    failure, a case that could not run an error, a missing device a skip; inconclusive and underpowered are
    failures too (their messages say so), since the case did not pass."""
    import xml.etree.ElementTree as ET

    counts = {s: sum(o.status == s for o in outcomes) for s in CaseStatus}
    root = ET.Element("testsuites")
    group = ET.SubElement(
        root,
        "testsuite",
        name=xml_text(suite),
        tests=str(len(outcomes)),
        failures=str(sum(n for s, n in counts.items() if STATUSES[s].junit == "failure")),
        errors=str(sum(n for s, n in counts.items() if STATUSES[s].junit == "error")),
        skipped=str(sum(n for s, n in counts.items() if STATUSES[s].junit == "skipped")),
        time=f"{sum(o.seconds for o in outcomes):.3f}",
    )
    for o in outcomes:
        case = ET.SubElement(group, "testcase", classname=xml_text(f"{suite}.{o.device}"), name=xml_text(o.case.name),
                             time=f"{o.seconds:.3f}")  # fmt: skip
        message = xml_text(o.message)
        element = STATUSES[o.status].junit
        if element == "failure":
            ET.SubElement(case, "failure", message=f"{o.verdict}: {message}", type=o.status)
        elif element == "error":
            ET.SubElement(case, "error", message=message, type="error")
        elif element == "skipped":
            ET.SubElement(case, "skipped", message=message)
        out = ET.SubElement(case, "system-out")
        out.text = message + (xml_text(f"\nreport: {Path(o.folder) / 'report.html'}") if o.folder else "")
    ET.indent(root)
    return ET.tostring(root, encoding="utf-8", xml_declaration=True)
