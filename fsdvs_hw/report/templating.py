"""The report's HTML templates: one Jinja2 environment, autoescaped, templates shipped as package data.

Every value a template prints is escaped (``autoescape`` for ``*.html.j2``), so a label, a file
name or a design value holding ``<`` or ``&`` shows as text; a fragment that is already HTML
(another template's output, a figure) is a :class:`markupsafe.Markup` and is kept. An undefined
name is an error (``StrictUndefined``), never an empty string. The templates live in
``fsdvs_hw/report/templates/`` (Jinja2 documentation: https://jinja.palletsprojects.com/).

Examples
--------
>>> from markupsafe import Markup
>>> str(render("macros.html.j2", macro="details", summary="a < b", body=Markup("<p>x</p>")))
'<details><summary>a &lt; b</summary><p>x</p></details>'
"""

from __future__ import annotations

import functools
from typing import Any
from urllib.parse import quote

import jinja2
from markupsafe import Markup

from .present import number, plain, point_title, si, title

__all__ = ["environment", "render"]


@functools.cache
def environment() -> jinja2.Environment:
    """The report's Jinja2 environment (built once): package templates, autoescape, strict undefined."""
    env = jinja2.Environment(
        loader=jinja2.PackageLoader("fsdvs_hw.report", "templates"),
        autoescape=jinja2.select_autoescape(enabled_extensions=("html.j2", "html"), default_for_string=True),
        undefined=jinja2.StrictUndefined,
        trim_blocks=True,
        lstrip_blocks=True,
    )
    env.globals.update(si=si, number=number, plain=plain, point_title=point_title, title=title, quote=quote)
    return env


def render(name: str, /, macro: str | None = None, **context: Any) -> Markup:
    """Render template ``name`` (or one of its macros, called with ``context`` as keywords) as HTML."""
    template = environment().get_template(name)
    if macro is not None:
        return Markup(getattr(template.module, macro)(**context))
    return Markup(template.render(**context))
