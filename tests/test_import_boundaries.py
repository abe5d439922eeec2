"""Who may import what between the ``drivers`` packages and from ``ffexp``.

Read from the sources with :mod:`ast` (every ``import`` and ``from ... import``, also
inside functions, relative ones resolved, and ``importlib.import_module("...")`` with a
literal name):

- ``ffexp`` imports from ``drivers`` only what :data:`FFEXP_ALLOWED` lists: the neutral
  packages, the rig, the factory and the registry. It is an allow-list, so a new back-end
  folder is forbidden to ``ffexp`` without editing this test.
- A back-end (any ``drivers/<name>/`` package that is not neutral and not
  ``drivers/emulate``) imports no sibling back-end and nothing that assembles back-ends;
  a robot family's emulated side (``drivers/<family>/emulate/``: its emulator, its
  controller's law on the simulated world, its in-process robot) may also import the
  emulated rig's shared parts (``drivers.emulate``). The simulated world itself
  (``drivers.world``) is neutral: it imports no back-end, so any may import it; the
  ``sim`` back-end is only the world's F/T sensor and tracker entries.
- ``drivers/emulate`` (the emulated rig: session, faults, Net F/T box, camera) imports no
  robot family: it finds them through :mod:`drivers.registry`.
- The neutral packages import no back-end, and the description and vision packages no
  MuJoCo and no sockets.
- ``drivers`` never imports ``ffexp``.

And rules on strings, since an import rule cannot see them: no string in ``ffexp``'s
code (docstrings aside) is a back-end's type, ``--driver`` name or emulated controller's
name, or holds a back-end's recording topic, all read from :mod:`drivers.registry` (so a
new back-end is covered at once), except the few :data:`STRING_EXCEPTIONS`. What ``ffexp``
needs of a back-end it reads from the back-end's declaration (link-fault counters, command
fields, its scene). In ``drivers``, such a name appears only in the folder of the back-end
that declares it (and the registry): a device asks a robot for what it offers
(``DeviceConfig.offers``), never for another back-end's type.
"""

from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path

from drivers import registry

ROOT = Path(__file__).resolve().parents[1]
DRIVERS = ROOT / "drivers"

#: Packages of ``drivers`` that are no back-end: anyone may import them (``carrier``: the
#: micro-gravity emulator's physics, pure maths on any robot's F/T and pose; ``world``: the
#: simulated world every family's emulated side steps).
NEUTRAL_PACKAGES = frozenset({"base", "net", "description", "vision", "carrier", "world"})
#: Top-level plumbing modules of ``drivers`` anyone may import.
NEUTRAL_MODULES = frozenset({"config", "errors", "counters"})
#: The emulated rig's shared parts (session, faults, the Net F/T box, the camera).
COMBINER = "emulate"
#: The back-ends the emulated rig's shared parts may import (the simulated world and the
#: Net F/T box's codec): devices of every emulated rig, no robot family.
COMBINER_MAY_IMPORT = frozenset({"sim", "netft"})
#: The sub-package of a robot family that is its emulated side, and what it may import
#: besides its own family and the neutral packages.
FAMILY_EMULATE = "emulate"
FAMILY_EMULATE_MAY_IMPORT = frozenset({COMBINER})
#: What ``ffexp`` may import from ``drivers`` (the second part of the dotted name).
FFEXP_ALLOWED = frozenset({"base", "config", "errors", "net", "rig", "factory", "registry",
                           "description", "vision", "carrier"})
#: Single ``ffexp`` modules allowed one more package, and why.
FFEXP_EXCEPTIONS = {
    # ``ffexp emulate`` serves the emulated rig (drivers.emulate.session.EmulatedRig);
    # drivers.emulate is the combiner, not one back-end
    "ffexp/cli/emulate.py": frozenset({COMBINER}),
    # a sweep's batch runs its runs through the simulated world's physics gate
    # (drivers.world.gate: neutral, no back-end; a run alone never imports it)
    "ffexp/sweeps/batch.py": frozenset({"world"}),
}
#: The strings ``ffexp`` code may hold although they name a back-end (file, string), and why.
STRING_EXCEPTIONS: dict[tuple[str, str], str] = {}
#: Modules the neutral description and vision packages must not use (no simulation, no I/O
#: beyond reading their files).
NEUTRAL_FORBIDDEN = ("mujoco", "socket", "drivers.sim", "drivers.world")


def imported_modules(source: str, module: str) -> Iterator[tuple[int, str]]:
    """(line, dotted name) of every module ``source`` imports; ``module`` is its own dotted
    name (to resolve relative imports). ``from a import b`` yields ``a.b`` as well as ``a``
    (``b`` may be a sub-module)."""
    package = module.rsplit(".", 1)[0]
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parent = package.split(".")
                parent = parent[: len(parent) - (node.level - 1)]
                base = ".".join([*parent, base] if base else parent)
            yield node.lineno, base
            for alias in node.names:
                yield node.lineno, f"{base}.{alias.name}"
        elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute | ast.Name)
              and (node.func.attr if isinstance(node.func, ast.Attribute) else node.func.id)
              == "import_module"
              and node.args and isinstance(node.args[0], ast.Constant)
              and isinstance(node.args[0].value, str)):
            yield node.lineno, node.args[0].value


def _sources(package: Path) -> Iterator[tuple[Path, str]]:
    for path in sorted(package.rglob("*.py")):
        rel = path.relative_to(ROOT).with_suffix("")
        parts = rel.parts[:-1] if rel.name == "__init__" else rel.parts
        yield path, ".".join(parts)


def _drivers_part(name: str) -> str | None:
    """``world`` for ``drivers.world.world``; None for names outside ``drivers``."""
    parts = name.split(".")
    return parts[1] if parts[0] == "drivers" and len(parts) > 1 else None


def backends() -> frozenset[str]:
    """Every back-end package: a ``drivers/<name>/`` package neither neutral nor the combiner."""
    return frozenset(
        p.name for p in DRIVERS.iterdir()
        if (p / "__init__.py").is_file() and p.name not in NEUTRAL_PACKAGES | {COMBINER}
    )


def ffexp_violations(source: str, module: str, rel: str) -> list[str]:
    """What ``source`` (module ``module``, file ``rel``) imports from ``drivers`` that
    ``ffexp`` may not."""
    allowed = FFEXP_ALLOWED | FFEXP_EXCEPTIONS.get(rel, frozenset())
    return _first_per_line(rel, [(line, name) for line, name in imported_modules(source, module)
                                 if (part := _drivers_part(name)) is not None
                                 and part not in allowed])


def _first_per_line(rel: str, hits: list[tuple[int, str]]) -> list[str]:
    """One message per import statement (``from a import b`` yields ``a`` and ``a.b``)."""
    first: dict[int, str] = {}
    for line, name in hits:
        first.setdefault(line, name)
    return [f"{rel}:{line}: imports {name}" for line, name in first.items()]


def backend_violations(source: str, module: str, rel: str, own: str,
                       all_backends: frozenset[str]) -> list[str]:
    """What a back-end's module imports of a sibling back-end, the combiner, the rig or
    factory (which assemble back-ends), or ``ffexp``; a family's emulated side
    (``drivers.<own>.emulate``) may import the combiner."""
    forbidden = (all_backends - {own}) | {COMBINER, "rig", "factory"}
    if module.split(".")[2:3] == [FAMILY_EMULATE]:
        forbidden -= FAMILY_EMULATE_MAY_IMPORT
    return _first_per_line(rel, [(line, name) for line, name in imported_modules(source, module)
                                 if name.split(".")[0] == "ffexp"
                                 or _drivers_part(name) in forbidden])


def test_ffexp_imports_only_the_allowed_drivers_packages() -> None:
    found = []
    for path, module in _sources(ROOT / "ffexp"):
        rel = path.relative_to(ROOT).as_posix()
        found += ffexp_violations(path.read_text(), module, rel)
    assert found == [], "\n".join(found)


def test_drivers_never_imports_ffexp() -> None:
    found = [f"{path.relative_to(ROOT).as_posix()}:{line}: imports {name}"
             for path, module in _sources(DRIVERS)
             for line, name in imported_modules(path.read_text(), module)
             if name.split(".")[0] == "ffexp"]
    assert found == [], "\n".join(found)


def test_no_backend_imports_a_sibling_backend_or_ffexp() -> None:
    every = backends()
    assert {"sim", "fri", "netft", "mock", "camera"} <= every  # the shipped back-ends are seen
    found = []
    for own in sorted(every):
        for path, module in _sources(DRIVERS / own):
            found += backend_violations(path.read_text(), module,
                                        path.relative_to(ROOT).as_posix(), own, every)
    assert found == [], "\n".join(found)


def test_the_emulated_rig_imports_no_robot_family() -> None:
    forbidden = (backends() - COMBINER_MAY_IMPORT) | {"rig", "factory"}
    found = []
    for path, module in _sources(DRIVERS / COMBINER):
        rel = path.relative_to(ROOT).as_posix()
        found += _first_per_line(rel, [(line, name) for line, name
                                       in imported_modules(path.read_text(), module)
                                       if _drivers_part(name) in forbidden
                                       or name.split(".")[0] == "ffexp"])
    assert found == [], "\n".join(found)


def test_the_import_checks_know_a_familys_emulated_side() -> None:
    source = ("from drivers.world.world import SimWorld\n"
              "from drivers.emulate.faults import F\n")
    every = frozenset({"fri", "sim", "ur"})
    assert backend_violations(source, "drivers.fri.emulate.server",
                              "drivers/fri/emulate/server.py", "fri", every) == []
    assert backend_violations(source, "drivers.fri.driver", "drivers/fri/driver.py", "fri",
                              every) == ["drivers/fri/driver.py:2: imports drivers.emulate.faults"]
    # the sim back-end (the world's sensor and tracker entries) is a sibling to a family,
    # its emulated side included
    assert backend_violations("from drivers.sim.tracker import SimTracker\n",
                              "drivers.fri.emulate.x", "x.py", "fri", every) == [
        "x.py:1: imports drivers.sim.tracker"]
    assert backend_violations("from drivers.ur.emulate import control\n",
                              "drivers.fri.emulate.x", "x.py", "fri", every) == [
        "x.py:1: imports drivers.ur.emulate"]


def test_the_neutral_packages_import_no_backend_and_no_simulation() -> None:
    every = backends() | {COMBINER, "rig", "factory"}
    found = []
    for package in sorted(NEUTRAL_PACKAGES):
        for path, module in _sources(DRIVERS / package):
            rel = path.relative_to(ROOT).as_posix()
            for line, name in imported_modules(path.read_text(), module):
                if _drivers_part(name) in every or name.split(".")[0] == "ffexp":
                    found.append(f"{rel}:{line}: imports {name}")
                if package in ("description", "vision") and any(
                        name == f or name.startswith(f + ".") for f in NEUTRAL_FORBIDDEN):
                    found.append(f"{rel}:{line}: imports {name}")
    assert found == [], "\n".join(found)


def test_the_checks_see_every_form_of_import() -> None:
    """The checker is not blind: imports in functions, relative, ``from drivers import x``
    and ``import_module`` are all seen, and a back-end folder not listed anywhere is
    forbidden to ffexp."""
    source = (
        "import drivers.base.types\n"
        "from drivers import sim\n"
        "def f():\n"
        "    from drivers.newarm.driver import Arm\n"
        "    import importlib\n"
        "    importlib.import_module('drivers.camera')\n"
        "from drivers.description import Scene\n"
    )
    got = ffexp_violations(source, "ffexp.thing", "ffexp/thing.py")
    assert got == ["ffexp/thing.py:2: imports drivers.sim",
                   "ffexp/thing.py:4: imports drivers.newarm.driver",
                   "ffexp/thing.py:6: imports drivers.camera"]
    relative = "from ..fri.codec import encode\nfrom . import world\nfrom ..base import types\n"
    got = backend_violations(relative, "drivers.sim.thing", "drivers/sim/thing.py", "sim",
                             frozenset({"sim", "fri"}))
    assert got == ["drivers/sim/thing.py:1: imports drivers.fri.codec"]
    assert backend_violations("from ffexp.errors import X\n", "drivers.sim.x", "x.py", "sim",
                              frozenset({"sim"})) == ["x.py:1: imports ffexp.errors"]


def backend_names() -> frozenset[str]:
    """Every back-end's rig type, ``--driver`` name and emulated controller's name (``none``,
    no tracker, is none)."""
    return frozenset({*registry.robot_types(), *registry.ft_types(), *registry.tracker_types(),
                      *registry.driver_names(), *(e.name for e in registry.emulators())}
                     - {"none"})


def names_by_folder() -> dict[str, frozenset[str]]:
    """The names (rig types, ``--driver`` names) each shipped back-end folder declares. (An
    emulated controller's name is its arm model's, which the neutral description package
    lists as every arm's; sessions find the controllers through the registry.)"""
    out: dict[str, frozenset[str]] = {}
    for b in registry.backends():
        if b.name not in registry.FOLDERS:
            continue
        out[b.name] = frozenset({*(r.rig_type for r in b.robots), *(r.driver for r in b.robots),
                                 *(s.rig_type for s in b.sensors),
                                 *(t.rig_type for t in b.trackers)})
    return out


def drivers_string_violations() -> list[str]:
    """Strings in ``drivers`` (docstrings aside) naming a back-end outside the folder that
    declares the name; the registry may name them all."""
    by_folder = names_by_folder()
    every = frozenset().union(*by_folder.values())
    found = []
    for path, module in _sources(DRIVERS):
        rel = path.relative_to(ROOT).as_posix()
        folder = module.split(".")[1] if module.count(".") else ""
        if module == "drivers.registry":
            continue
        own = by_folder.get(folder, frozenset())
        found += string_violations(path.read_text(), rel, every - own, frozenset())
    return found


def backend_topics() -> frozenset[str]:
    """Every back-end's recording topics."""
    return frozenset(t.topic for t in (*registry.backend_cdr_topics(),
                                       *registry.backend_json_topics()))


def _docstrings(tree: ast.AST) -> set[int]:
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
            first = node.body[0] if node.body else None
            if (isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant)
                    and isinstance(first.value.value, str)):
                found.add(id(first.value))
    return found


def _default_fts(tree: ast.AST) -> set[int]:
    """The ``default_ft="..."`` of robot entries: the built-in rig of ``--driver`` may pair a
    robot with another back-end's sensor (its rig's default, not a closed list)."""
    return {id(k.value) for node in ast.walk(tree) if isinstance(node, ast.Call)
            for k in node.keywords if k.arg == "default_ft" and isinstance(k.value, ast.Constant)}


def string_violations(source: str, rel: str, names: frozenset[str],
                      topics: frozenset[str]) -> list[str]:
    """Each string of ``source`` (file ``rel``) that is one of ``names`` or holds one of
    ``topics``, docstrings, a robot's ``default_ft`` and :data:`STRING_EXCEPTIONS` aside."""
    tree = ast.parse(source)
    docs = _docstrings(tree) | _default_fts(tree)
    found = []
    for node in ast.walk(tree):
        if (not isinstance(node, ast.Constant) or not isinstance(node.value, str)
                or id(node) in docs or (rel, node.value) in STRING_EXCEPTIONS):
            continue
        if node.value in names or any(t in node.value for t in topics):
            found.append(f"{rel}:{node.lineno}: names a back-end: {node.value!r}")
    return found


def test_ffexp_names_no_backend_and_no_backend_topic() -> None:
    names, topics = backend_names(), backend_topics()
    assert {"fri1", "ur", "ur-sim", "sim", "fri-estimate"} <= names  # the shipped ones are seen
    assert {"/robot/command", "/robot/link", "/robot/link_driver", "/robot/ur"} <= topics
    found = []
    for path, _module in _sources(ROOT / "ffexp"):
        rel = path.relative_to(ROOT).as_posix()
        found += string_violations(path.read_text(), rel, names, topics)
    assert found == [], "\n".join(found)


def test_drivers_name_a_backend_only_in_its_own_folder() -> None:
    """No closed list of another family's types: a new family touches no other folder."""
    found = drivers_string_violations()
    assert found == [], "\n".join(found)


def test_the_drivers_string_check_sees_another_familys_name() -> None:
    by_folder = names_by_folder()
    assert "ur-sim" in by_folder["ur"] and "ur-sim" not in by_folder["sim"]
    got = string_violations('def f(robot):\n    return robot.type in ("sim", "ur-sim")\n',
                            "drivers/sim/backend.py", backend_names() - by_folder["sim"],
                            frozenset())
    assert got == ["drivers/sim/backend.py:2: names a back-end: 'ur-sim'"]


def test_every_string_exception_is_still_needed() -> None:
    names, topics = backend_names(), backend_topics()
    for rel, text in STRING_EXCEPTIONS:
        source = (ROOT / rel).read_text()
        assert text in names or any(t in text for t in topics), (rel, text)
        assert any(isinstance(n, ast.Constant) and n.value == text
                   for n in ast.walk(ast.parse(source))), f"{rel}: no {text!r} any more"


def test_the_string_check_sees_names_and_topics_but_not_docstrings() -> None:
    source = (
        '"""Reads /robot/link (FRI)."""\n'
        'def f(rec, kind):\n'
        '    """The fri1 robot\'s link."""\n'
        '    if kind == "fri1":\n'
        '        return rec.topics.get(f"{kind}/robot/link_driver")\n'
        '    return "sim-like", "/robot/state"\n'
    )
    got = string_violations(source, "ffexp/thing.py", frozenset({"fri1", "sim"}),
                            frozenset({"/robot/link", "/robot/link_driver"}))
    assert got == ["ffexp/thing.py:4: names a back-end: 'fri1'",
                   "ffexp/thing.py:5: names a back-end: '/robot/link_driver'"]


#: The project's type aliases and the one module that declares each.
ALIAS_HOMES = {
    **dict.fromkeys(("Vec3", "Vec6", "Bool6", "PosFloat", "NonNeg", "Port", "Floats2",
                     "Floats3", "Floats6", "PerJoint"), "drivers/config.py"),
    "F64": "drivers/base/types.py",
    "FloatArray": "",  # F64's old second name: declared nowhere
    "Six": "",  # Vec6's old second name
}
#: Files that still declare an alias of their own, and why.
ALIAS_EXCEPTIONS: frozenset[str] = frozenset()


def alias_declarations(source: str, rel: str) -> list[str]:
    """Module-level assignments to an :data:`ALIAS_HOMES` name outside its home."""
    found = []
    for node in ast.parse(source).body:
        targets = (node.targets if isinstance(node, ast.Assign)
                   else [node.target] if isinstance(node, ast.AnnAssign) else [])
        for target in targets:
            if (isinstance(target, ast.Name) and target.id in ALIAS_HOMES
                    and ALIAS_HOMES[target.id] != rel):
                found.append(f"{rel}:{node.lineno}: declares {target.id} again")
    return found


def test_each_type_alias_is_declared_once() -> None:
    found = []
    for package in ("drivers", "ffexp"):
        for path, _module in _sources(ROOT / package):
            rel = path.relative_to(ROOT).as_posix()
            if rel not in ALIAS_EXCEPTIONS:
                found += alias_declarations(path.read_text(), rel)
    assert found == [], "\n".join(found)
    assert alias_declarations("Vec6 = tuple[float, ...]\nx: int = 1\n", "ffexp/x.py") == [
        "ffexp/x.py:1: declares Vec6 again"]
