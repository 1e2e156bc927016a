"""MkDocs hooks of the docs site (``hooks:`` in ``mkdocs.yml``).

- The generated references: a page's marker ``<!-- generated: NAME -->`` is replaced by
  the Markdown that ``docs/gen_reference.py`` writes from the code (the scenario keys
  from their ``Param`` declarations, the command line from its argparse parser), at
  every build, so the pages cannot drift from the code.
- The pictures: the GIFs and figures of the repository's ``renders/`` and
  ``studies/figures/`` are added to the site as they are (nothing is copied into
  ``docs/``); a page links them relatively, ``../renders/rotating_circle.gif`` from a
  page one folder down.
- The docstrings' Sphinx roles (``:func:`load_scenario```): mkdocstrings renders the
  name as code and leaves the role's text before it; the role is dropped.
- The changelog: ``docs/changelog.md`` includes the top-level ``CHANGELOG.md`` (through
  the ``pymdownx.snippets`` extension, whose base path is the repository).
"""

from __future__ import annotations

import importlib.util
import re
import sys
from pathlib import Path

from mkdocs.structure.files import File

ROOT = Path(__file__).resolve().parent.parent
#: Repository folders whose pictures the site serves under the same paths.
PICTURES = ("renders", "studies/figures")
SUFFIXES = {".gif", ".png", ".svg", ".jpg", ".mp4"}
MARKER = re.compile(r"<!-- generated: ([a-z-]+) -->")
#: A Sphinx cross-reference role left in a docstring (``:func:`name```), as rendered.
ROLE = re.compile(r":(?:mod|func|class|meth|data|attr|exc|obj|const):(?=<code>)")


def _generators():
    spec = importlib.util.spec_from_file_location(
        "gen_reference", Path(__file__).with_name("gen_reference.py")
    )
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("gen_reference", module)
    spec.loader.exec_module(module)
    return module.GENERATORS


def on_config(config):
    """Read the snippets (``CHANGELOG.md``) from the repository, whatever the cwd."""
    snippets = config["mdx_configs"].setdefault("pymdownx.snippets", {})
    snippets["base_path"] = [str(ROOT)]
    return config


def on_files(files, config):
    """Serve the pictures of ``renders/`` and ``studies/figures/`` at those paths."""
    for folder in PICTURES:
        for path in sorted((ROOT / folder).rglob("*")):
            if path.is_file() and path.suffix.lower() in SUFFIXES:
                files.append(
                    File(
                        path.relative_to(ROOT).as_posix(),
                        src_dir=str(ROOT),
                        dest_dir=config["site_dir"],
                        use_directory_urls=config["use_directory_urls"],
                    )
                )
    return files


def on_page_markdown(markdown, page, config, files):
    """Replace each ``<!-- generated: NAME -->`` marker by its generated Markdown."""
    if "<!-- generated:" not in markdown:
        return markdown
    generators = _generators()

    def generate(match: re.Match) -> str:
        name = match.group(1)
        if name not in generators:
            raise ValueError(f"{page.file.src_uri}: no generator named {name!r}")
        return generators[name]()

    return MARKER.sub(generate, markdown)


def on_page_content(html, page, config, files):
    """Drop the text of Sphinx roles (``:func:``) in front of the names they mark."""
    return ROLE.sub("", html)
