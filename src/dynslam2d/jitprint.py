"""llvmlite's LLVM IR printer and numba's ABI-size queries with less Python work (issue 13 item 2, docs/speed.md pass
cmp39).

numba hands every module it lowers to LLVM as text: ``CPUCodeLibrary.add_ir_module`` prints the llvmlite IR module
(``str(ir_module)``) and parses the text back (``llvmlite.binding.parse_assembly``). A cold run of the README's first
command prints 165 such modules once each (≈ 368 000 instructions, 28 MB of text), ≈ 2.3 s of one core: per
instruction llvmlite calls ``_StrCaching.__str__`` (an ``AttributeError`` raised and caught on the first print),
``NamedValue._to_string``, the class's ``descr`` with a list buffer and ``str.format``, which formats each operand's
type and reference through two more Python calls (the reference's first lookup raising ``AttributeError`` too).
Separately, ``Type.get_abi_size`` (numba's ``get_abi_sizeof``, ≈ 3700 calls for 32 distinct types, ≈ 0.5 s) prints a
one-variable module and parses it with LLVM for every call.

- :func:`fast_blocks` replaces ``llvmlite.ir.Block.descr`` (each basic block's text, which ``Function.__str__``
  joins) with :func:`block_descr`: an instruction of the 14 most common classes (extract / insert value, load,
  store, GEP, integer and float compare, alloca, the arithmetic instructions, branches, return, select, cast) gets
  llvmlite's text from one f-string with the same pieces in the same order (the type and reference strings read
  from, and written to, llvmlite's own caches on the objects, as llvmlite's lookups would); any other instruction
  goes through llvmlite's ``str``. Every instruction's text is stored in its ``_StrCaching`` slot as llvmlite does.
- :func:`abi_sizes` remembers ``Type.get_abi_size`` / ``get_abi_alignment`` per type text and target data when the
  module llvmlite would parse is determined by the type's text alone (a type with no identified struct in it, the
  context holding no identified types): the result is then a function of that text and the data layout.

- :func:`lean_meminfos` (pass cmp43) has numba's reference counts extract from a value only the members that can hold
  a meminfo: the same ``incref`` / ``decref`` calls, ≈ 70 000 fewer dead instructions per cold run, the same machine
  code, except in the kernels of :data:`NUMBA_MEMINFOS_IN`, which keep numba's own lowering (numba's sources checked,
  :data:`MEMINFO_SOURCES`).

- :func:`constant_calls` (pass cmp48) has ``Type.__call__`` (a constant of the type) build llvmlite's ``Constant``
  without importing it at each of its ≈ 125 000 calls per cold run.

The first two and the last only when llvmlite's ``ir`` files have the SHA-256 checked here (:data:`SOURCES`) and the
replaced methods are llvmlite's own; otherwise llvmlite is left as it is. ``benchmarks/check_jitprint.py`` compares the
text and the caches left on every object for every module of a cold run, and every ABI query, with llvmlite's own
code (``--dump D --asm [--numba-meminfos]``: every library's assembly, to compare with numba's own reference counts).
"""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any

#: SHA-256 (first 16 hex digits) of the llvmlite 0.50 files whose code :func:`block_descr` and :func:`abi_sizes`
#: reproduce or rely on: ``values.py`` (``Block``, ``NamedValue``, ``Constant``, ``GlobalVariable``),
#: ``instructions.py`` (each class's ``descr``), ``types.py`` (type strings, ``_get_ll_global_value_type``),
#: ``_utils.py`` (the string caches, ``_stringify_metadata``) and ``module.py`` (the module text).
SOURCES = {"values": "bfe6f9a13ddb4716", "instructions": "93400736d3aaf0f8", "types": "0efe6957ae3c3280",
           "_utils": "9a4a7210c950f671", "module": "fb970383103cddaf"}

_STR = "_StrCaching__cached_str"  # llvmlite's cache slots (``_StrCaching.__cached_str``, name-mangled)
_REF = "_StringReferenceCaching__cached_refstr"
_CHECKED: dict[tuple[tuple[str, str], ...], bool] = {}


def _sources_checked() -> bool:
    """Whether llvmlite's ``ir`` files have the SHA-256 in :data:`SOURCES` (read once per value of it)."""
    key = tuple(sorted(SOURCES.items()))
    if key not in _CHECKED:
        try:
            from llvmlite.ir import _utils, instructions, module, types, values

            files = {"values": values, "instructions": instructions, "types": types, "_utils": _utils,
                     "module": module}
            _CHECKED[key] = all(hashlib.sha256(Path(files[name].__file__).read_bytes()).hexdigest()[:16] == digest
                                for name, digest in SOURCES.items())
        except (ImportError, OSError, TypeError):  # pragma: no cover - llvmlite is a dependency
            _CHECKED[key] = False
    return _CHECKED[key]


def _setup() -> tuple[Any, Any, Any, dict[type, Any]]:
    """llvmlite's cache methods, ``VoidType`` and the instruction classes :func:`block_descr` formats itself, each
    with its formatter (a class is left out when its ``descr``, ``_to_string`` or ``__str__`` is not llvmlite's)."""
    from llvmlite.ir import _utils, types, values
    from llvmlite.ir import instructions as li

    cached_ref, cached_str = _utils._StringReferenceCaching.get_reference, _utils._StrCaching.__str__
    void = types.VoidType
    ref_ok: dict[type, bool] = {}
    str_ok: dict[type, bool] = {}

    def ref(v: Any) -> str:  # v.get_reference(), llvmlite's cache read and written as llvmlite does
        cls = type(v)
        ok = ref_ok.get(cls)
        if ok is None:
            ok = ref_ok[cls] = cls.get_reference is cached_ref
        if ok:
            s = v.__dict__.get(_REF)
            if s is None:
                s = v._StringReferenceCaching__cached_refstr = v._get_reference()
            return s
        return v.get_reference()

    def text(t: Any) -> str:  # str(t) (what "{0}".format(t) gives), llvmlite's cache read and written likewise
        cls = type(t)
        ok = str_ok.get(cls)
        if ok is None:
            ok = str_ok[cls] = cls.__str__ is cached_str
        if ok:
            s = t.__dict__.get(_STR)
            if s is None:
                s = t._StrCaching__cached_str = t._to_string()
            return s
        return str(t)

    def head(i: Any) -> str:  # NamedValue._to_string's "{0} = ".format(self.get_reference()) for a non-void value
        return "" if isinstance(i.type, void) else ref(i) + " = "

    def meta(i: Any) -> str:  # _stringify_metadata(leading_comma=True): '' without metadata
        return i._stringify_metadata(leading_comma=True) if i.metadata else ""

    # Each: NamedValue._to_string of the class, "".join([head, <descr's text>]).rstrip(), descr's pieces in order.
    def extract_value(i: Any) -> str:
        agg = i.aggregate
        indices = ", ".join(map(str, i.indices))
        return f"{head(i)}extractvalue {text(agg.type)} {ref(agg)}, {indices} {meta(i)}\n".rstrip()

    def insert_value(i: Any) -> str:
        agg, val = i.aggregate, i.value
        return (f"{head(i)}insertvalue {text(agg.type)} {ref(agg)}, {text(val.type)} {ref(val)}, "
                f"{', '.join(map(str, i.indices))} {meta(i)}\n").rstrip()

    def load(i: Any) -> str:
        [val] = i.operands
        align = "" if i.align is None else ", align %d" % (i.align)  # noqa: UP031 (llvmlite's expression)
        return f"{head(i)}load {text(i.type)}, {text(val.type)} {ref(val)}{align}{meta(i)}\n".rstrip()

    def store(i: Any) -> str:
        val, ptr = i.operands
        align = "" if i.align is None else ", align %d" % (i.align)  # noqa: UP031 (llvmlite's expression)
        return f"{head(i)}store {text(val.type)} {ref(val)}, {text(ptr.type)} {ref(ptr)}{align}{meta(i)}\n".rstrip()

    def gep(i: Any) -> str:
        ptr = i.pointer
        indices = ", ".join([f"{text(x.type)} {ref(x)}" for x in i.indices])
        op = "getelementptr inbounds" if i.inbounds else "getelementptr"
        return f"{head(i)}{op} {text(i.source_etype)}, {text(ptr.type)} {ref(ptr)}, {indices} {meta(i)}\n".rstrip()

    def compare(i: Any) -> str:
        lhs, rhs = i.operands[0], i.operands[1]
        flags = "".join(" " + it for it in i.flags)
        return f"{head(i)}{i.opname}{flags} {i.op} {text(lhs.type)} {ref(lhs)}, {ref(rhs)} {meta(i)}\n".rstrip()

    def alloca(i: Any) -> str:
        s = f"{head(i)}{i.opname} {text(i.allocated_type)}"
        if i.operands:
            op, = i.operands
            s += f", {text(op.type)} {ref(op)}"
        if i.align is not None:
            s += f", align {i.align}"
        if i.metadata:
            s += i._stringify_metadata(leading_comma=True)
        return s.rstrip()

    def instruction(i: Any) -> str:
        opname = i.opname
        if i.flags:
            opname = " ".join([opname] + i.flags)
        return f"{head(i)}{opname} {text(i.type)} {', '.join([ref(op) for op in i.operands])}{meta(i)}\n".rstrip()

    def terminator(i: Any) -> str:
        return f"{head(i)}{i.opname} {', '.join([f'{text(op.type)} {ref(op)}' for op in i.operands])}{meta(i)}".rstrip()

    def ret(i: Any) -> str:
        val = i.return_value
        if val is not None:
            return f"{head(i)}{i.opname} {text(val.type)} {ref(val)}{meta(i)}\n".rstrip()
        return f"{head(i)}{i.opname}{meta(i)}\n".rstrip()

    def select(i: Any) -> str:
        c, a, b = i.operands[0], i.operands[1], i.operands[2]
        return (f"{head(i)}select {' '.join(i.flags)} {text(c.type)} {ref(c)}, {text(a.type)} {ref(a)}, "
                f"{text(b.type)} {ref(b)} {meta(i)}\n").rstrip()

    def cast(i: Any) -> str:
        op = i.operands[0]
        return f"{head(i)}{i.opname} {text(op.type)} {ref(op)} to {text(i.type)} {meta(i)}\n".rstrip()

    table = {li.ExtractValue: (extract_value, "ExtractValue.descr"),
             li.InsertValue: (insert_value, "InsertValue.descr"), li.LoadInstr: (load, "LoadInstr.descr"),
             li.StoreInstr: (store, "StoreInstr.descr"), li.GEPInstr: (gep, "GEPInstr.descr"),
             li.ICMPInstr: (compare, "CompareInstr.descr"), li.FCMPInstr: (compare, "CompareInstr.descr"),
             li.AllocaInstr: (alloca, "AllocaInstr.descr"), li.Instruction: (instruction, "Instruction.descr"),
             li.Branch: (terminator, "Terminator.descr"), li.ConditionalBranch: (terminator, "Terminator.descr"),
             li.Ret: (ret, "Ret.descr"), li.SelectInstr: (select, "SelectInstr.descr"),
             li.CastInstr: (cast, "CastInstr.descr")}
    fast = {cls: f for cls, (f, qual) in table.items()
            if getattr(cls.descr, "__qualname__", None) == qual and cls.descr.__module__ == li.__name__
            and cls._to_string is values.NamedValue._to_string and cls.__str__ is cached_str
            and cls.__format__ is object.__format__}
    return ref, text, void, fast


_FAST: dict[type, Any] = {}


def block_descr(self: Any, buf: list[str]) -> None:
    """llvmlite's ``Block.descr``: the block's label line and each instruction's line (``"  {0}\\n".format(instr)``),
    the common instruction classes formatted by :func:`_setup`'s formatters (same text, same caches written)."""
    buf.append(f"{self._format_name()}:\n")
    get = _FAST.get
    for ins in self.instructions:
        fmt = get(type(ins))
        if fmt is None:
            buf.append(f"  {ins}\n")  # ("  {0}\n".format(ins))
            continue
        s = ins.__dict__.get(_STR)
        if s is None:
            s = ins._StrCaching__cached_str = fmt(ins)
        buf.append(f"  {s}\n")


def fast_blocks() -> bool:
    """Have llvmlite print basic blocks with :func:`block_descr` (llvmlite's sources checked, ``Block.descr``
    llvmlite's own). Returns whether it changed llvmlite (not when called again)."""
    from llvmlite.ir import values

    descr = values.Block.descr
    if getattr(descr, "_dynslam2d_fast", False) or not _sources_checked():
        return False
    if getattr(descr, "__qualname__", None) != "Block.descr" or descr.__module__ != values.__name__:
        return False
    _FAST.update(_setup()[3])
    block_descr._dynslam2d_fast = True  # type: ignore[attr-defined]
    block_descr.__wrapped__ = descr  # type: ignore[attr-defined]
    values.Block.descr = block_descr
    return True


#: ``(kind, type text, id(target data))`` -> (target data, result) of :func:`abi_sizes`' queries.
_ABI: dict[tuple[str, str, int], tuple[Any, int]] = {}


def _abi_key(t: Any, context: Any) -> str | None:
    """The text of type ``t`` when llvmlite's ``_get_ll_global_value_type`` would parse a module determined by it
    alone (``@"foo" = external global <text>``, no type declarations: the context holds no identified types and the
    text names none), else None."""
    from llvmlite import ir

    ctx = ir.global_context if context is None else context
    if getattr(ctx, "identified_types", True) or type(t)._get_ll_global_value_type is not _GLOBAL_TYPE[0]:
        return None
    s = str(t)
    return None if "%" in s else s


_GLOBAL_TYPE: list[Any] = [None]


def abi_sizes() -> bool:
    """Have llvmlite's ``Type.get_abi_size`` and ``get_abi_alignment`` remember their result per type text and target
    data when :func:`_abi_key` gives one (llvmlite's sources checked, the methods llvmlite's own). Returns whether it
    changed llvmlite (not when called again)."""
    from llvmlite.ir import types

    size, align = types.Type.get_abi_size, types.Type.get_abi_alignment
    if getattr(size, "_dynslam2d_abi", False) or not _sources_checked():
        return False
    if (size.__qualname__, align.__qualname__) != ("Type.get_abi_size", "Type.get_abi_alignment"):
        return False
    _GLOBAL_TYPE[0] = types.Type._get_ll_global_value_type

    def remembered(kind: str, query: Any) -> Any:
        def method(self: Any, target_data: Any, context: Any = None) -> int:
            text = _abi_key(self, context)
            if text is None:
                return query(self, target_data, context)
            key = (kind, text, id(target_data))
            hit = _ABI.get(key)
            if hit is not None and hit[0] is target_data:
                return hit[1]
            value = query(self, target_data, context)
            _ABI[key] = (target_data, value)  # (target data kept alive: its id is not reused)
            return value

        method._dynslam2d_abi = True  # type: ignore[attr-defined]
        method.__wrapped__ = query  # type: ignore[attr-defined]
        method.__qualname__ = f"remembered.{query.__name__}"
        return method

    types.Type.get_abi_size = remembered("size", size)  # type: ignore[method-assign]
    types.Type.get_abi_alignment = remembered("align", align)  # type: ignore[method-assign]
    return True


#: SHA-256 (first 16 hex digits) of the source of the numba 0.68 methods :func:`lean_meminfos` reproduces
#: (``NRTContext.get_meminfos``) or relies on (the data models' ``traverse``: the member types it lists do not depend
#: on the builder, and nothing is emitted until a getter is called).
MEMINFO_SOURCES = {"NRTContext.get_meminfos": "4681e04e53a8b209", "DataModel.traverse": "08a7001b07cce7d1",
                   "UniTupleModel.traverse": "124a6ba7aa2c09cb", "StructModel.traverse": "0d7305fcf43d2f37",
                   "OptionalModel.traverse": "f2ca15e9f8af1561"}


def _meminfo_sources() -> tuple[Any, tuple[Any, ...]] | None:
    """numba's ``NRTContext.get_meminfos`` and the ``traverse`` methods named in :data:`MEMINFO_SOURCES` when their
    sources are the ones checked; else None."""
    import inspect

    try:
        from numba.core.datamodel import models
        from numba.core.runtime import context
    except ImportError:  # pragma: no cover - numba is a dependency
        return None
    found = {"NRTContext.get_meminfos": context.NRTContext.get_meminfos,
             "DataModel.traverse": models.DataModel.traverse, "UniTupleModel.traverse": models.UniTupleModel.traverse,
             "StructModel.traverse": models.StructModel.traverse,
             "OptionalModel.traverse": models.OptionalModel.traverse}
    for name, func in found.items():
        try:
            source = inspect.getsource(func)
        except (OSError, TypeError):
            return None
        if hashlib.sha256(source.encode()).hexdigest()[:16] != MEMINFO_SOURCES.get(name):
            return None
    return found["NRTContext.get_meminfos"], tuple(v for k, v in found.items() if k.endswith(".traverse"))


#: Kernels (``module.function``) whose reference counts keep numba's own ``get_meminfos``, dead extracts included:
#: in ``raycast.integrate_levels`` the dead extracts of an array's shape and strides, emitted at the ``incref`` right
#: after a level's array is picked from a tuple, are where LLVM's common-subexpression elimination merges the
#: kernel's later extracts of the same fields; without them the register allocation of its level loop changes and
#: its map update was 3-5 % slower in lockstep (docs/speed.md, passes cmp40 and cmp43). Every other library's
#: assembly is the same either way (``benchmarks/check_jitprint.py --dump DIR --asm [--numba-meminfos]``).
NUMBA_MEMINFOS_IN = frozenset({"dynslam2d.slam.raycast.integrate_levels"})


def _mangled_stems(name: str) -> tuple[str, str]:
    """The starts of the mangled names numba gives function ``name`` (``module.function``) and its CPython wrapper,
    without the ABI tags and argument types that follow (``B…`` / ``E…``)."""
    from numba.core.funcdesc import default_mangler

    stem = default_mangler(name, ())[:-1]  # ("_ZN9dynslam2d…16integrate_levelsE" without its "E")
    return stem, "_ZN7cpython" + stem[3:]


def lean_meminfos() -> bool:
    """Have numba's reference-count lowering extract from a value only the members that hold a reference-counted
    pointer; returns whether it changed numba (not when called again, nor when numba's sources differ).

    ``NRTContext.get_meminfos`` (every ``incref`` / ``decref`` numba emits: ≈ 50 000 on a cold run of the README's
    first command) walks the value's data model and, for every member, emits the member's ``extractvalue`` (an
    optional's ``select``) before looking into it: all seven fields of an array's struct and every element of its
    shape and strides tuples, of which only the meminfo pointer is used; the rest is dead code that llvmlite builds
    and prints and LLVM parses and deletes. :func:`lean_get_meminfos` asks first whether a member's type can hold a
    meminfo (the same walk over the models' member types, remembered per type) and emits the getter only for those:
    the same list of ``(type, meminfo)``, the same ``incref`` / ``decref`` calls on the same values, without the dead
    instructions. Only models whose ``traverse`` is one of numba's checked ones are skipped; any other member is
    extracted as numba does, and so is every member in the kernels of :data:`NUMBA_MEMINFOS_IN`."""
    found = _meminfo_sources()
    if found is None or getattr(found[0], "_dynslam2d_meminfos", False):
        return False
    from numba.core.runtime import context

    original, known = found
    known_set = set(known)

    def needs(dmm: Any, ty: Any) -> bool:
        """Whether numba's ``get_meminfos`` can return a meminfo for a value of type ``ty`` (conservative: True)."""
        memo = dmm.__dict__.setdefault("_dynslam2d_meminfo", {})
        hit = memo.get(ty)
        if hit is not None:
            return hit
        model = dmm[ty]
        if type(model).traverse not in known_set:
            memo[ty] = True
            return True
        memo[ty] = True  # (while walking: a type met again inside itself counts as holding one)
        result = bool(model.has_nrt_meminfo()) or any(needs(dmm, member) for member, _ in model.traverse(None))
        memo[ty] = result
        return result

    stems = tuple(stem for name in NUMBA_MEMINFOS_IN for stem in _mangled_stems(name))
    kept: dict[str, bool] = {}

    def lean_get_meminfos(self: Any, builder: Any, ty: Any, val: Any) -> list[Any]:
        fname = builder.function.name
        keep = kept.get(fname)
        if keep is None:
            keep = kept[fname] = any(fname.startswith(s) and fname[len(s):len(s) + 1] in ("B", "E") for s in stems)
        if keep:
            return original(self, builder, ty, val)
        dmm = self._context.data_model_manager
        if not needs(dmm, ty):
            return []
        datamodel = dmm[ty]
        members = datamodel.traverse(builder)
        meminfos = []
        if datamodel.has_nrt_meminfo():
            mi = datamodel.get_nrt_meminfo(builder, val)
            meminfos.append((ty, mi))
        for mtyp, getter in members:
            if needs(dmm, mtyp):
                meminfos.extend(self.get_meminfos(builder, mtyp, getter(val)))
        return meminfos

    lean_get_meminfos._dynslam2d_meminfos = True  # type: ignore[attr-defined]
    lean_get_meminfos.__wrapped__ = original  # type: ignore[attr-defined]
    context.NRTContext.get_meminfos = lean_get_meminfos  # type: ignore[method-assign]
    return True


def constant_calls() -> bool:
    """Have llvmlite's ``Type.__call__`` (``ir.IntType(64)(0)``: a constant of the type) build the ``Constant`` without
    importing it at each call (llvmlite 0.50 runs ``from llvmlite.ir import Constant`` in the method: CPython's
    ``_handle_fromlist`` in Python, ≈ 0.5 µs, ≈ 125 000 calls on a cold run of the README's first command). The class
    is the one that import returns (``llvmlite.ir.Constant``, read at install), so the constant is the same object
    llvmlite makes. Only when llvmlite's sources have the SHA-256 in :data:`SOURCES`, the method is llvmlite's own,
    no subclass of ``Type`` defines its own ``__call__`` and ``llvmlite.ir.Constant`` is ``values.Constant``.
    Returns whether it changed llvmlite (not when called again)."""
    import llvmlite.ir as ir
    from llvmlite.ir import types, values

    call = types.Type.__call__
    if getattr(call, "_dynslam2d_constant", False) or not _sources_checked():
        return False
    if getattr(call, "__qualname__", None) != "Type.__call__" or call.__module__ != types.__name__:
        return False
    if ir.Constant is not values.Constant or _own_calls(types.Type):
        return False
    constant = ir.Constant

    def type_call(self: Any, value: Any) -> Any:
        return constant(self, value)

    type_call._dynslam2d_constant = True  # type: ignore[attr-defined]
    type_call.__wrapped__ = call  # type: ignore[attr-defined]
    type_call.__doc__ = call.__doc__
    types.Type.__call__ = type_call  # type: ignore[method-assign]
    return True


def _own_calls(cls: type) -> bool:
    """Whether a subclass of ``cls`` (at any depth) defines ``__call__``."""
    return any("__call__" in sub.__dict__ or _own_calls(sub) for sub in cls.__subclasses__())


def install() -> bool:
    """Install :func:`fast_blocks`, :func:`abi_sizes`, :func:`lean_meminfos` and :func:`constant_calls`; returns
    whether any was installed. Called by :func:`dynslam2d.jitcache.lean_numba_compile` at the first compile."""
    done = [fast_blocks(), abi_sizes(), lean_meminfos(), constant_calls()]
    return any(done)
