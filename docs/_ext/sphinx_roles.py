"""A griffe extension for the API reference: Sphinx roles in docstrings as code.

grainforge's numpydoc docstrings name other objects with Sphinx roles
(``:func:`fso```, ``:class:`~grainforge.grain.Grain```, ``:mod:`.fourier```).
Markdown has no such roles, so mkdocstrings would print them as they are
written.  This extension rewrites each role to an inline code span of the name
it shows (for ``~a.b.c``, the last part ``c``; for ``title <target>``, the
title) before the docstring is parsed.  The source files are not changed.
"""

from __future__ import annotations

import re

from griffe import Extension

#: a Sphinx role: :func:`x`, :py:meth:`~a.b`, :class:`title <a.b>`
ROLE = re.compile(r":(?:py:)?(?:func|class|mod|meth|attr|data|obj|exc|const):`([^`]+)`")


def _shown(target: str) -> str:
    target = target.strip()
    titled = re.fullmatch(r"(.*?)\s*<([^>]+)>", target)
    if titled:
        return titled.group(1)
    if target.startswith("~"):
        return target[1:].rsplit(".", 1)[-1]
    return target


def rewrite_roles(text: str) -> str:
    """Every Sphinx role in ``text`` as a Markdown code span of the name it shows.

    >>> rewrite_roles(":func:`fso` and :class:`~grainforge.grain.Grain`")
    '`fso` and `Grain`'
    """
    return ROLE.sub(lambda m: f"`{_shown(m.group(1))}`", text)


class SphinxRoles(Extension):
    """Rewrite Sphinx roles in every docstring griffe loads."""

    def on_instance(self, *, obj, **kwargs) -> None:  # griffe's hook, called once per object
        if obj.docstring is not None:
            obj.docstring.value = rewrite_roles(obj.docstring.value)
