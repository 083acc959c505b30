"""The configuration reference page, generated from ``conf/`` so that it cannot drift.

``python -m tactile_exp.config_reference > docs/configuration.md`` rewrites the page; a test
fails when the committed page differs from what this module generates. It lists every config
group and option with the comments its YAML carries, the paper's numbered method items those
comments cite (their text from ``docs/method.md``) and every value marked "ours" (where the paper
is silent or we differ). Comments are read from the YAML text itself: a YAML parser drops them.
"""

from __future__ import annotations

import json
import re
import sys
from dataclasses import dataclass
from pathlib import Path

from tactile_exp import marks

ROOT = Path(__file__).resolve().parent.parent
CONF = ROOT / "conf"
METHOD = ROOT / "docs" / "method.md"
COMMAND = "python -m tactile_exp.config_reference > docs/configuration.md"
# Groups Hydra itself reads (the --help text), not options of a job.
SKIP_GROUPS = ("hydra",)
_ITEM = re.compile(r"^- ([DPVMTE]\d+)\. (.*)$")
_CITE = re.compile(r"\b([DPVMTE])(\d+)(?:-\1?(\d+))?\b")
_OURS = re.compile(r"\bours\b", re.IGNORECASE)
_KEY = re.compile(r"^(\s*)([A-Za-z_][\w.]*):")
_DEFAULT = re.compile(r"^\s*-\s*(?:override\s+)?/?([\w/]+):\s*([\w.]+)")


@dataclass(frozen=True)
class Option:
    """One YAML file of a config group."""

    group: str
    name: str
    path: Path
    text: str

    @property
    def summary(self) -> str:
        """The file's leading comment block, one line (the option's description)."""
        lines = []
        for line in self.text.splitlines():
            if line.startswith("# @package"):
                continue
            if not line.startswith("#"):
                break
            lines.append(line.lstrip("#").strip())
        return " ".join(lines)


def method_items(path: Path = METHOD) -> dict[str, str]:
    """The numbered method items (``P1`` -> its text, continuation lines joined)."""
    items: dict[str, str] = {}
    current = None
    for line in path.read_text().splitlines():
        if m := _ITEM.match(line):
            current = m.group(1)
            items[current] = m.group(2).strip()
        elif current and line.startswith("  ") and line.strip():
            items[current] += " " + line.strip()
        else:
            current = None
    return items


def cited(text: str, known: dict[str, str]) -> list[str]:
    """Method items a text cites, ranges (``P1-P6``) expanded, in order of first mention."""
    found: list[str] = []
    for letter, first, last in _CITE.findall(text):
        for n in range(int(first), int(last or first) + 1):
            item = f"{letter}{n}"
            if item in known and item not in found:
                found.append(item)
    return found


def options(conf: Path = CONF) -> dict[str, list[Option]]:
    """Every group (folder under ``conf/``, nested ones as ``a/b``) and its option files."""
    groups: dict[str, list[Option]] = {}
    for path in sorted(conf.rglob("*.yaml")):
        rel = path.relative_to(conf)
        if len(rel.parts) == 1 or rel.parts[0] in SKIP_GROUPS:
            continue
        group = "/".join(rel.parts[:-1])
        groups.setdefault(group, []).append(Option(group, path.stem, path, path.read_text()))
    return groups


def defaults(conf: Path = CONF) -> dict[str, str]:
    """The default option of each group, from ``config.yaml``'s defaults list."""
    found = {}
    for line in (conf / "config.yaml").read_text().splitlines():
        if (m := _DEFAULT.match(line)) and m.group(2) != "null":
            found[m.group(1)] = m.group(2)
    return found


def ours(text: str) -> list[tuple[str, str]]:
    """``(key, comment)`` for every comment that says "ours". A comment beside a value belongs to
    its key (with the comment lines continuing it below); a comment block above a key to that
    key, the file's opening block to the file (key ``-``)."""
    lines = text.splitlines()
    keys: list[str] = []  # each line's key path, "" for lines without a key
    stack: list[tuple[int, str]] = []
    for line in lines:
        m = _KEY.match(line)
        if m:
            indent = len(m.group(1))
            stack = [(d, k) for d, k in stack if d < indent] + [(indent, m.group(2))]
        keys.append(".".join(k for _, k in stack) if m else "")
    is_comment = [line.strip().startswith("#") for line in lines]
    found, i = [], 0
    while i < len(lines):
        if is_comment[i]:  # a comment block, for the key below it (or the file's, at the top)
            j = i
            while j < len(lines) and (is_comment[j] or not lines[j].strip()):
                j += 1
            block = " ".join(c.split("#", 1)[1].strip() for c in lines[i:j] if c.strip())
            header = not any(lines[k].strip() and not is_comment[k] for k in range(i))
            key = "-" if header or j == len(lines) else keys[j] or "-"
            if _OURS.search(block):
                found.append((key, block.removeprefix("@package _global_ ").strip()))
            i = j
            continue
        if "#" in lines[i]:  # a comment beside a value, maybe continued below at its column
            col = lines[i].index("#")
            comment = [lines[i][col + 1 :].strip()]
            j = i + 1
            while j < len(lines) and is_comment[j] and lines[j].index("#") == col > 0:
                comment.append(lines[j][col + 1 :].strip())
                j += 1
            if _OURS.search(" ".join(comment)):
                key = keys[i] or next((k for k in reversed(keys[:i]) if k), "-")
                found.append((key, " ".join(comment)))
            i = j
            continue
        i += 1
    return found


def _fence(text: str) -> list[str]:
    return ["```yaml", text.rstrip("\n"), "```", ""]


def marks_table() -> list[str]:
    """Each setting's marks (``tactile_exp/marks.py``): what the config hash, run names, the
    training key and a search make of it."""
    out = [
        "### What each setting is to a job",
        "",
        "Marked once in `tactile_exp/marks.py` ([adding a setting](extending.md#a-setting));",
        "the config hash (a finished job is skipped), run names, the training key (a trained",
        "model is reused) and a search's fixed keys all derive from these marks. A top-level",
        "key without a mark is refused; a component parameter without one is hashed and keyed.",
        "Training key `-`: not a model's or modality's parameter (what reaches a model, such as",
        "`schedule` or `seed`, is keyed through the model's own node).",
        "",
        "| key | config hash | run name | training key | search |",
        "|---|---|---|---|---|",
    ]
    for key, mark in marks.MARKS.items():
        hashed = "yes" if mark.hashed else "no"
        if mark.hashed_unless is not marks.UNSET:
            hashed = f"unless {json.dumps(mark.hashed_unless)}"
        keyed = (
            "-" if key.split(".")[0] not in marks.KEYED_GROUPS else "yes" if mark.keyed else "no"
        )
        search = [f"fixed: {mark.fixed}"] if mark.fixed else []
        search += ["set by the search, not its final run"] if mark.search_only else []
        named = "yes" if mark.named else "no"
        out.append(f"| `{key}` | {hashed} | {named} | {keyed} | {'; '.join(search)} |")
    return [*out, ""]


def generate(conf: Path = CONF, method: Path = METHOD) -> str:
    """The whole page, Markdown."""
    items = method_items(method)
    groups = options(conf)
    chosen = defaults(conf)
    top = (conf / "config.yaml").read_text()
    out = [
        "# Configuration reference",
        "",
        f"<!-- Generated from conf/ by `{COMMAND}`; do not edit by hand. -->",
        "",
        f"Generated from `conf/` by `{COMMAND}` (a test fails when this page is stale). Every",
        "value can be overridden on the command line: `group=option` picks a file of a group,",
        "`key=value` sets a value (`schedule.epochs=20`, `adjectives=[hard,soft]`).",
        "`python -m tactile_exp --cfg job` prints the resolved config and",
        "`--info defaults-tree` where each value comes from. Method items (P1, T3, ...) are the",
        'paper\'s numbered steps in [the method](method.md); "ours" marks a value the paper does',
        "not fix or where we differ from it",
        "([all of them](#ours-where-the-paper-is-silent-or-we-differ)).",
        "",
        "## Top level: `conf/config.yaml`",
        "",
        "The defaults list picks one option per group; the plain values follow it.",
        "",
        *_fence(top),
        *marks_table(),
        "## Groups",
        "",
        "| group | options (default in bold) |",
        "|---|---|",
    ]
    for group, opts in groups.items():
        names = [f"**`{o.name}`**" if chosen.get(group) == o.name else f"`{o.name}`" for o in opts]
        out.append(f"| [`{group}`](#{group.replace('/', '')}) | {', '.join(names)} |")
    out.append("")
    for group, opts in groups.items():
        out += [f"### {group}", ""]
        if group in chosen:
            out += [f"Default: `{group}={chosen[group]}`.", ""]
        out += ["| option | what it selects | method items |", "|---|---|---|"]
        for o in opts:
            refs = ", ".join(cited(o.text, items))
            out.append(f"| `{group}={o.name}` | {o.summary.replace('|', '/')} | {refs} |")
        out.append("")
        for o in opts:
            out += [f"#### `{group}={o.name}`", "", f"`conf/{group}/{o.name}.yaml`:", ""]
            out += _fence(o.text)
    all_text = top + "".join(o.text for opts in groups.values() for o in opts)
    out += [
        "## Method items the configs cite",
        "",
        "Their text as [the method](method.md) states it.",
        "",
        "| item | what the paper does |",
        "|---|---|",
    ]
    for item in sorted(cited(all_text, items), key=lambda i: ("DPVMTE".index(i[0]), int(i[1:]))):
        out.append(f"| {item} | {items[item]} |")
    out += [
        "",
        "## Ours: where the paper is silent or we differ",
        "",
        'Every comment in `conf/` that says "ours", with the key it sits on',
        "(`-`: the file's own comment).",
        "",
        "| file | key | comment |",
        "|---|---|---|",
    ]
    for path in [conf / "config.yaml", *(o.path for opts in groups.values() for o in opts)]:
        for key, comment in ours(path.read_text()):
            rel = path.relative_to(conf)
            out.append(f"| `conf/{rel}` | `{key}` | {comment.replace('|', '/')} |")
    return "\n".join(out) + "\n"


def main() -> None:
    sys.stdout.write(generate())


if __name__ == "__main__":
    main()
