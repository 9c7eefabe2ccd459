"""MkDocs hooks (mkdocs.yml ``hooks:``): links between pages inside a rendered notebook.

mkdocs-jupyter renders a notebook with nbconvert, outside MkDocs' Markdown, so a Markdown
cell's link to another page ("python-api.md", "../reference/schema.md#anchor") reaches the
site as written and points at a source file the site does not have (mkdocs-jupyter issue
157). Written that way the link works in Jupyter and on GitHub; this rewrites it on the site
into the target page's URL, as MkDocs does for a Markdown page, and logs a warning (which
fails ``mkdocs build --strict``) for a link to no page of the site. Anchors are kept as they
are, not checked."""

from __future__ import annotations

import logging
import posixpath
import re
from typing import Any

log = logging.getLogger(f"mkdocs.plugins.{__name__}")

LINK = re.compile(r'(<a\s[^>]*?href=")([^":?#]+\.(?:md|ipynb))(#[^"]*)?"')
"""A relative link to a page's source: a path ending in .md or .ipynb (no scheme, no query),
its anchor if any."""


def site_link(href: str, page_src: str, files: Any, page_file: Any) -> str | None:
    """The site URL, relative to the page, of the page whose source ``href`` names (relative to
    the page's source ``page_src``), or None if the site has no such page."""
    target = posixpath.normpath(posixpath.join(posixpath.dirname(page_src), href))
    file = files.get_file_from_path(target)
    if file is None or not file.is_documentation_page():
        return None
    url: str = file.url_relative_to(page_file)
    return url


def on_page_content(html: str, page: Any, config: Any, files: Any) -> str:
    """A notebook page's links to other pages' sources, made the site's links."""
    source = page.file.src_uri
    if not source.endswith(".ipynb"):
        return html

    def rewrite(match: re.Match[str]) -> str:
        url = site_link(match.group(2), source, files, page.file)
        if url is None:
            log.warning("%s links to '%s', which is no page of the site", source, match.group(2))
            return match.group(0)
        return f'{match.group(1)}{url}{match.group(3) or ""}"'

    return LINK.sub(rewrite, html)
