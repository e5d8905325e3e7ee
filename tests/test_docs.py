"""The documentation keeps up with the code: every CLI command and option is documented,
every relative link resolves, the README stays short, and the module map matches the tree."""

from __future__ import annotations

import re
import unicodedata
from pathlib import Path

import pytest
import typer

from viewdb_cli.main import app

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"
CLI_DOC = ROOT / "docs" / "cli.md"
ARCHITECTURE = ROOT / "docs" / "architecture.md"
README_MAX_LINES = 250

LINK = re.compile(r"!?\[(?:[^\]\\]|\\.)*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
FENCE = re.compile(r"^(```|~~~).*?^\1", re.S | re.M)
INLINE_CODE = re.compile(r"`[^`\n]*`")
HEADING = re.compile(r"^(#{1,6})\s+(.*?)\s*#*\s*$", re.M)


def _group() -> typer.core.TyperGroup:
    return typer.main.get_command(app)


def _commands() -> dict[str, object]:
    return dict(_group().commands)


def _option_names(params: list) -> list[str]:
    """Each option's long name (``--name``), or its short name when it has none."""
    names = []
    for p in params:
        if p.param_type_name != "option":
            continue
        opts = [*p.opts, *p.secondary_opts]
        longs = [o for o in opts if o.startswith("--")]
        names.extend(longs or opts[:1])
    return names


def _docs() -> list[Path]:
    return [README, *sorted((ROOT / "docs").rglob("*.md"))]


def _prose(text: str) -> str:
    """Markdown without fenced code blocks and inline code (where a link is not a link)."""
    return INLINE_CODE.sub("", FENCE.sub("", text))


def _slug(heading: str) -> str:
    """GitHub's anchor for a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", heading)  # a link's text only
    text = text.replace("`", "").strip().lower()
    kept = "".join(ch for ch in text
                   if ch in " -_" or unicodedata.category(ch)[0] in ("L", "N"))
    return kept.replace(" ", "-")


def _anchors(path: Path) -> set[str]:
    seen: dict[str, int] = {}
    out = set()
    for _, title in HEADING.findall(FENCE.sub("", path.read_text(encoding="utf-8"))):
        slug = _slug(title)
        n = seen.get(slug, 0)
        seen[slug] = n + 1
        out.add(slug if n == 0 else f"{slug}-{n}")
    return out


def _cli_sections() -> dict[str, str]:
    """``docs/cli.md`` split at its ``## viewdb ...`` headings: heading text -> body."""
    text = CLI_DOC.read_text(encoding="utf-8")
    parts = re.split(r"^## +(.+?)\s*$", text, flags=re.M)
    return {parts[i].strip(): parts[i + 1] for i in range(1, len(parts) - 1, 2)}


def _readme_cli_table() -> dict[str, str]:
    """The README's CLI table: command name -> its row."""
    rows = {}
    for line in README.read_text(encoding="utf-8").splitlines():
        match = re.match(r"\|\s*`viewdb ([a-z][a-z-]*)", line)
        if match:
            rows[match.group(1)] = line
    return rows


def test_the_cli_has_commands_to_check():
    assert {"ingest", "query", "serve"} <= set(_commands())


@pytest.mark.parametrize("name", sorted(_commands()))
def test_every_command_is_in_the_readme_cli_table(name):
    assert name in _readme_cli_table(), f"README.md: the CLI table has no row for `viewdb {name}`"


@pytest.mark.parametrize("name", sorted(_commands()))
def test_every_command_and_option_is_in_docs_cli(name):
    sections = _cli_sections()
    assert f"viewdb {name}" in sections, f"docs/cli.md: no '## viewdb {name}' section"
    body = sections[f"viewdb {name}"]
    missing = [o for o in _option_names(_commands()[name].params)
               if not re.search(rf"`{re.escape(o)}(?![\w-])", body)]
    assert not missing, f"docs/cli.md, viewdb {name}: options not documented: {', '.join(missing)}"


def test_global_options_are_in_docs_cli():
    body = _cli_sections().get("viewdb (global options)", "")
    missing = [o for o in _option_names(_group().params) if f"`{o}`" not in body]
    assert not missing, f"docs/cli.md: global options not documented: {', '.join(missing)}"


def test_docs_cli_documents_no_command_that_does_not_exist():
    documented = {h.split()[1] for h in _cli_sections() if h.startswith("viewdb ") and "(" not in h}
    assert documented <= set(_commands()), f"docs/cli.md: no such commands: {documented - set(_commands())}"


@pytest.mark.parametrize("doc", _docs(), ids=lambda p: str(p.relative_to(ROOT)))
def test_every_relative_link_points_at_an_existing_file(doc):
    broken = []
    for target in LINK.findall(_prose(doc.read_text(encoding="utf-8"))):
        if re.match(r"[a-z][a-z0-9+.-]*:", target, re.I):  # http:, https:, mailto: ...
            continue
        path, _, anchor = target.partition("#")
        dest = doc if not path else (doc.parent / path).resolve()
        if not dest.exists():
            broken.append(f"{target} (no such file)")
        elif anchor and dest.suffix == ".md" and anchor not in _anchors(dest):
            broken.append(f"{target} (no heading #{anchor})")
    assert not broken, f"{doc.relative_to(ROOT)}: broken links: {'; '.join(broken)}"


def test_readme_is_short():
    lines = len(README.read_text(encoding="utf-8").splitlines())
    assert lines <= README_MAX_LINES, f"README.md has {lines} lines, more than {README_MAX_LINES}"


def test_readme_links_every_doc():
    text = README.read_text(encoding="utf-8")
    unlinked = [p.name for p in sorted((ROOT / "docs").glob("*.md")) if f"](docs/{p.name}" not in text]
    assert not unlinked, f"README.md does not link {', '.join(unlinked)}"


def test_the_module_map_matches_the_tree():
    text = ARCHITECTURE.read_text(encoding="utf-8")
    section = re.search(r"^## Module map$(.*?)(?=^## |\Z)", text, re.M | re.S)
    assert section, "docs/architecture.md has no '## Module map' section"
    listed = set(re.findall(r"^- `(viewdb/[\w/]+\.py)`", section.group(1), re.M))
    tree = {str(p.relative_to(ROOT)) for p in (ROOT / "viewdb").rglob("*.py") if p.name != "__init__.py"}
    assert not tree - listed, f"docs/architecture.md: modules missing from the map: {sorted(tree - listed)}"
    assert not listed - tree, f"docs/architecture.md: modules that do not exist: {sorted(listed - tree)}"
