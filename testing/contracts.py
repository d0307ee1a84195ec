"""The extension contracts as data, read from their code (issue 48 item 3).

A kind's contract is two classes (:mod:`fbia.core.protocols`): its protocol, whose methods a
plugin must write, and its base, whose attributes and methods a plugin may override (their
values and bodies are the defaults; a ``@final`` one is the framework's).  :func:`contracts`
reads them, with their docstrings, into :class:`Member` records; the registry and the checks
of this kit test plugins against the same classes, and ``docs/plugins.md``'s member tables
are :func:`contract_tables` (``tests/core/test_contracts.py`` compares them)::

    >>> from fbia.testing.contracts import contracts
    >>> [m.name for m in contracts()["measure"] if m.role == "required"]
    ['Options', 'residuals(simulated, observation)', 'distance(simulated, observation)']
    >>> {m.name: m.default for m in contracts()["measure"]}["dims"]
    '(2, 3)'
"""

from __future__ import annotations

import ast
import inspect
import re
import textwrap
from dataclasses import dataclass
from typing import Literal

from ..core.iteration import Evaluator, IteratorBase
from ..core.options import Configurable
from ..core.problem import IteratorMembers
from ..core.protocols import (
    Discrepancy,
    ForwardModel,
    ForwardModelBase,
    InverseIterator,
    MeasureBase,
)

__all__ = ["Member", "contract", "contract_table", "contract_tables", "contracts"]

Role = Literal["required", "optional", "framework"]

#: The title of each contract in the tables of ``docs/plugins.md``.
TITLES = {
    "forward_model": "Forward model: derive from `fbia.ForwardModelBase`",
    "measure": "Measure: derive from `fbia.MeasureBase`",
    "iterator": "Iterator: derive from `fbia.IteratorBase`",
    "evaluator": "The evaluator an iterator's `steps` receives",
}


@dataclass(frozen=True)
class Member:
    """One member of a contract: its name (``solve(parameters, coordinates, workdir)`` for a
    method), who writes it, the base's value for an optional attribute, and the first
    paragraph of its docstring (for an optional method it says what the base's does)."""

    name: str
    role: Role
    default: str = ""
    doc: str = ""

    @property
    def attribute(self) -> str:
        """The attribute the plugin class carries (``solve`` for ``solve(...)``)."""
        return self.name.partition("(")[0]


def contract(protocol: type, base: type | None = None) -> tuple[Member, ...]:
    """The members of one contract, in the order of the code: ``Options`` (with a base) and
    the protocol's members, required; then what the base and the classes between it and
    :class:`fbia.Configurable` define, optional, or the framework's where ``@final``."""
    required: list[Member] = []
    if base is not None:
        required.append(_member(Configurable, "Options", "required"))
    required += [_member(protocol, name, "required") for name in _public(protocol)]
    seen = {m.attribute for m in required}
    rest: list[Member] = []
    for cls in reversed(base.__mro__ if base is not None else ()):
        if not issubclass(cls, Configurable):
            continue
        for name in _public(cls):
            if name not in seen:
                seen.add(name)
                rest.append(_member(cls, name, "optional"))
    return (*required, *rest)


def contracts() -> dict[str, tuple[Member, ...]]:
    """Kind -> its contract (:func:`contract`), and ``evaluator``: what an iterator's
    ``steps`` receives (:class:`fbia.core.iteration.Evaluator`)."""
    return {
        "forward_model": contract(ForwardModel, ForwardModelBase),
        "measure": contract(Discrepancy, MeasureBase),
        "iterator": (
            *contract(InverseIterator, IteratorMembers),
            _member(IteratorBase, "run", "optional"),
        ),
        "evaluator": contract(Evaluator),
    }


def contract_table(kind: str) -> str:
    """The contract of ``kind`` as a Markdown table: member, who writes it, the default of an
    optional attribute, what it is."""
    lines = ["| member | role | default | what it is |", "|---|---|---|---|"]
    for m in contracts()[kind]:
        default = f"`{m.default}`" if m.default else ""
        lines.append(f"| `{m.name}` | {m.role} | {default} | {_markdown(m.doc)} |")
    return "\n".join(lines)


def contract_tables() -> str:
    """Every contract's table under its title: the generated part of ``docs/plugins.md``."""
    return "\n\n".join(f"**{TITLES[kind]}**\n\n{contract_table(kind)}" for kind in contracts())


def _public(cls: type) -> list[str]:
    """The public names ``cls`` itself defines, in the order of its code."""
    return [n for n in vars(cls) if not n.startswith("_")]


def _member(cls: type, name: str, role: Role) -> Member:
    value = vars(cls)[name]
    function = value.__func__ if isinstance(value, classmethod | staticmethod) else value
    function = function.fget if isinstance(function, property) else function
    if inspect.isfunction(function):
        final = getattr(function, "__final__", False)  # typing.final's mark: the framework's
        role = "framework" if final and role == "optional" else role
        if isinstance(value, property):
            return Member(name, role, "", _first_paragraph(function.__doc__))
        params = list(inspect.signature(function).parameters.values())
        shown = params if isinstance(value, staticmethod) else params[1:]
        signature = ", ".join(p.name if p.default is p.empty else f"{p.name}={p.default!r}"
                              for p in shown)  # fmt: skip
        return Member(f"{name}({signature})", role, "", _first_paragraph(function.__doc__))
    default = value.__qualname__ if isinstance(value, type) else repr(value)
    return Member(name, role, "" if role == "required" else default, _attribute_docs(cls)[name])


def _attribute_docs(cls: type) -> dict[str, str]:
    """The docstrings of ``cls``'s attributes (the string below an assignment, as Sphinx and
    mkdocstrings read them), by name, from its source."""
    definition = ast.parse(textwrap.dedent(inspect.getsource(cls))).body[0]
    assert isinstance(definition, ast.ClassDef)
    body, docs = definition.body, {}
    for node, after in zip(body, body[1:], strict=False):
        target: ast.expr | None = None
        if isinstance(node, ast.AnnAssign):
            target = node.target
        elif isinstance(node, ast.Assign) and len(node.targets) == 1:
            target = node.targets[0]
        if (
            isinstance(target, ast.Name)
            and isinstance(after, ast.Expr)
            and isinstance(after.value, ast.Constant)
            and isinstance(after.value.value, str)
        ):
            docs[target.id] = _first_paragraph(after.value.value)
    return docs


def _first_paragraph(doc: str | None) -> str:
    text = inspect.cleandoc(doc or "")
    return " ".join(text.split("\n\n")[0].split())


#: a reST role around a name (class, meth, func, mod, attr; its target with or without a
#: leading tilde), which a table of ``docs/plugins.md`` shows as Markdown code
_ROLE = re.compile(r":[a-z]+:`~?([^`]+)`")


def _markdown(text: str) -> str:
    return _ROLE.sub(r"`\1`", text).replace("``", "`").replace("|", "\\|")
