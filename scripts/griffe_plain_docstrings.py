"""A griffe extension for the docs build: pelletdem's docstrings are plain text with a little
Markdown (``code``, *emphasis*, **bold**, bullet lists) and some reStructuredText habits.

mkdocstrings renders a docstring as Markdown, where the formulas' asterisks (r* for the
equivalent radius, band * D) would start emphasis and swallow text, and the reStructuredText
definition lists (a term line, then its text indented by four spaces) would become code
blocks. This extension escapes every asterisk that is not part of an emphasis span or a
bullet, turns :func:`x` and its kin into code spans, and renders a definition's term in bold
with its text as paragraphs, so the pages read like the docstrings do in `help()`. Indented
blocks after a blank line stay code blocks (command lines, examples).
"""
from __future__ import annotations

import re

import griffe

_ROLE = re.compile(r":(?:func|class|data|mod|attr|meth|obj|exc):`~?([^`]+)`")
# Code spans, strong and emphasis spans (an opener not preceded and a closer not followed by a
# word character, as Markdown reads them): kept as they are.
_KEEP = re.compile(r"``.+?``|`[^`]+`|(?<![\w*])\*\*(?=\S).+?(?<=\S)\*\*(?![\w*])"
                   r"|(?<![\w*])\*(?=[^\s*]).*?(?<=[^\s*])\*(?![\w*])")
_BULLET = re.compile(r"^(\s*)\* ")


def _indent(line: str) -> int:
    return len(line) - len(line.lstrip(" "))


def _prose(line: str) -> str:
    line = _ROLE.sub(r"`\1`", line)
    bullet = _BULLET.match(line)
    head, body = (line[:bullet.end()], line[bullet.end():]) if bullet else ("", line)
    parts, last = [], 0
    for m in _KEEP.finditer(body):
        parts.append(body[last:m.start()].replace("*", "\\*"))
        parts.append(m.group(0))
        last = m.end()
    parts.append(body[last:].replace("*", "\\*"))
    return head + "".join(parts)


def plain(text: str) -> str:
    """`text` made safe for Markdown (see the module docstring)."""
    lines = text.splitlines()
    out: list[str] = []
    definition = code = False
    for k, line in enumerate(lines):
        blank = not line.strip()
        nxt = lines[k + 1] if k + 1 < len(lines) else ""
        if blank:
            out.append(line)
            code = code and not definition
            continue
        ind = _indent(line)
        if definition and ind < 4:
            definition = False
        if definition:
            out.append(_prose(line[4:]))
            continue
        if ind >= 4 and (code or (k > 0 and not lines[k - 1].strip())):
            code = True
            out.append(line)
            continue
        code = False
        if ind == 0 and nxt.strip() and _indent(nxt) >= 4:
            definition = True
            out.extend([f"**{_prose(line.strip())}**", ""])
            continue
        out.append(_prose(line))
    return "\n".join(out)


class PlainDocstrings(griffe.Extension):
    """Apply `plain` to every docstring griffe loads."""

    def on_instance(self, *, obj, **kwargs) -> None:
        if obj.docstring is not None:
            obj.docstring.value = plain(obj.docstring.value)
