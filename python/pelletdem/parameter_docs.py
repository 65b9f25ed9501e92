"""The laws' parameter tables as Markdown for the docs (docs/parameters.md is made with them
when the site is built): each row of a law's C++ table, with the candidate effect it belongs
to, if any."""
from __future__ import annotations

from .effects import EFFECTS
from .laws import ContactLaw, allowed_values

__all__ = ["markdown_table"]


def markdown_table(law) -> str:
    """``law``'s parameter table (ContactLaw or BondLaw) as a Markdown table: field, unit,
    default, allowed values and what it is, with the candidate effect it belongs to, if any
    (docs/parameters.md is made with it)."""
    prefix = "contact." if law is ContactLaw else "bond."
    owner = {}
    for e in EFFECTS.values():
        for p in (e.param, *e.fixed):
            if p.startswith(prefix):
                owner[p[len(prefix):]] = e
    lines = ["| field | unit | default | allowed | what it is |", "|---|---|---|---|---|"]
    for r in law.rows():
        default = str(bool(r.default)) if r.type == "bool" else f"{r.default:g}"
        doc = r.doc
        e = owner.get(r.name)
        if e is not None:
            doc += f" (candidate effect `{e.name}`, acting in the {e.stage} stage)"
        lines.append(f"| `{r.name}` | {r.unit} | {default} | {allowed_values(r)} | {doc} |")
    return "\n".join(lines)
