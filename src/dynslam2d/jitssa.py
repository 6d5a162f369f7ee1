"""numba's SSA reconstruction, variable lists, use / def sets and live-variable map with less Python work (issue 13
item 2).

A cold run of the README's first command spends about a second of one core's CPU in numba's ``reconstruct_ssa`` pass,
as much again listing the variables of IR statements (``ir.Inst._rec_list_vars``: about four million recursive calls,
most of them from ``analysis.compute_use_defs``) and over a second in ``analysis.compute_live_map``; docs/speed.md,
passes cold35, cold36, ssa36 and uni36 (which left one implementation of each here). Four source-checked
replacements, installed by :func:`install` at the first compile of the command line's processes
(:func:`dynslam2d.jitcache.lean_numba_compile`):

- :func:`sparse_run_ssa` replaces ``numba.core.ssa._run_ssa``. numba's pass rewrites, for every variable assigned
  more than once (a "violator"), every statement of every block twice (fresh names for its definitions, then the
  reaching definition at each use). A statement that neither defines nor uses the violator comes out of both passes
  as the same object, with no change to the pass's state, so only the statements that do go through numba's own
  handlers, in numba's order; every block numba would rebuild is rebuilt, and every block is a new ``ir.Block`` at
  the end, as numba's last pass leaves them. The same IR, names, phi nodes and warnings (``tests/test_jitssa.py``,
  ``benchmarks/check_jitssa.py``).
- :func:`fast_list_vars` gives ``ir.Inst._rec_list_vars`` and the ``list_vars`` of ``ir.Stmt`` and ``ir.Expr`` one
  traversal that appends to a single list instead of a list per visited value: the same variables in the same order.
- :func:`lean_use_defs`: ``analysis.compute_use_defs`` lists an assignment's variables once instead of twice.
- :func:`bit_live_map`: ``analysis.compute_live_map``'s fixed points over bit masks instead of sets of names.
- :func:`lazy_lifetimes` (pass cmp70): ``PostProcessor.run`` leaves the variable lifetimes (use / def sets, live and
  dead maps, block entry variables) to numba's lazy ``VariableLifetime`` where nothing reads them: ≈ 780 of ≈ 1 130
  computations per cold run skipped, the same IR and code.

All are done only when numba's ``ssa.py``, ``ir.py``, ``ir_utils.py`` and ``analysis.py`` have the SHA-256 checked
here (numba 0.68, :data:`SOURCES`); otherwise numba is left as it is.
"""

from __future__ import annotations

import hashlib
from collections import defaultdict
from pathlib import Path
from typing import Any

#: SHA-256 (first 16 hex digits) of the numba files whose code the replacements reproduce or rely on (numba 0.68.1):
#: ``ssa.py`` (the pass and its handlers), ``ir.py`` (``list_vars``, ``Block``, ``Scope.redefine``, the copy
#: semantics of ``Expr``), ``ir_utils.py`` (``replace_vars_inner`` / ``replace_vars_stmt``, which the handlers call)
#: and ``analysis.py`` (``compute_use_defs``, ``compute_live_map``).
SOURCES = {"ssa": "d20accd92757fef6", "ir": "e6c8061cecb65e68", "ir_utils": "6deaf6b1d9401cc4",
           "analysis": "04b7eefad8abb7c9"}

#: SHA-256 (first 16 hex digits) of the numba files :func:`shared_cfg` reproduces (numba 0.68.1): ``postproc.py``
#: (``PostProcessor.run``, ``VariableLifetime``) and ``transforms.py`` (``canonicalize_cfg``).
POSTPROC_SOURCES = {"postproc": "d83593cf83ef70f4", "transforms": "4d579adc3f819863"}

#: How many functions' SSA reconstruction went through numba's own ``_run_ssa`` after the check in
#: :func:`sparse_run_ssa` found IR objects shared between statements (see there); for tests and benchmarks.
FALLBACKS = [0]


def _sources_checked() -> bool:
    """Whether numba's files have the SHA-256 in :data:`SOURCES` (read once per value of :data:`SOURCES`)."""
    key = tuple(sorted(SOURCES.items()))
    if key not in _CHECKED:
        _CHECKED[key] = _read_and_check()
    return _CHECKED[key]


_CHECKED: dict[tuple[tuple[str, str], ...], bool] = {}


def _read_and_check() -> bool:
    try:
        from numba.core import analysis, ir, ir_utils, ssa
    except ImportError:  # pragma: no cover - numba is a dependency
        return False
    for name, module in (("ssa", ssa), ("ir", ir), ("ir_utils", ir_utils), ("analysis", analysis)):
        try:
            data = Path(module.__file__).read_bytes()
        except (OSError, TypeError):
            return False
        if hashlib.sha256(data).hexdigest()[:16] != SOURCES[name]:
            return False
    return True


def fast_list_vars() -> bool:
    """Have numba list an IR node's variables (``ir.Inst._rec_list_vars``, ``ir.Stmt.list_vars``,
    ``ir.Expr.list_vars``) in one traversal appending to one list.

    numba's ``_rec_list_vars`` returns a new list for every value it visits (each variable, each location, each
    argument list) and extends its caller's list with it; here one recursive helper appends every variable to the
    list being built, in the same pre-order (attributes or keyword values in their dict order, list and tuple items
    in order), reaching an instruction nested in another through its own ``list_vars`` as numba does (inline when it
    is numba's ``Stmt`` or ``Expr`` one). The same ``ir.Var`` objects in the same order. Done only when numba's sources
    are those checked (:data:`SOURCES`). Returns whether it changed numba (not when called again)."""
    from numba.core import ir

    if getattr(ir.Inst, "_dynslam2d_fast", False) or not _sources_checked():
        return False
    Var, Inst = ir.Var, ir.Inst
    kinds: dict[type, int] = {}  # type -> 1 Var, 2 instruction, 3 list or tuple, 4 dict, 0 other (isinstance order)

    def kind_of(t: type) -> int:
        k = 1 if issubclass(t, Var) else 2 if issubclass(t, Inst) else 3 if issubclass(t, (list, tuple)) else (
            4 if issubclass(t, dict) else 0)
        kinds[t] = k
        return k

    def collect(val: Any, out: list[Any]) -> None:  # numba's _rec_list_vars(val), appended to ``out``
        t = type(val)
        k = kinds.get(t)
        if k is None:
            k = kind_of(t)
        if k == 3:
            seq = val
        elif k == 4:
            seq = val.values()
        elif k == 2:
            lv = t.list_vars
            if t._rec_list_vars is rec_list_vars and lv is stmt_list_vars:
                seq = val.__dict__.values()
            elif t._rec_list_vars is rec_list_vars and lv is expr_list_vars:
                seq = val._kws.values()
            else:
                out.extend(val.list_vars())
                return
        elif k == 1:
            out.append(val)
            return
        else:
            return
        for v in seq:
            if type(v) is Var:
                out.append(v)
            elif kinds.get(type(v), 5):  # not a type known to hold no variables
                collect(v, out)

    def rec_list_vars(self: Any, val: Any) -> list[Any]:
        """A recursive helper used to implement list_vars() in subclasses (numba's, as one traversal)."""
        t = type(val)
        k = kinds.get(t)
        if k is None:
            k = kind_of(t)
        if k == 2 and not (t._rec_list_vars is rec_list_vars
                           and (t.list_vars is stmt_list_vars or t.list_vars is expr_list_vars)):
            return val.list_vars()  # numba returns the instruction's own list
        out: list[Any] = []
        if k:
            collect(val, out)
        return out

    def stmt_list_vars(self: Any) -> list[Any]:
        """List the variables used (read or written) by the instruction (numba's ``Stmt.list_vars``)."""
        if type(self)._rec_list_vars is not rec_list_vars:
            return self._rec_list_vars(self.__dict__)
        out: list[Any] = []
        for v in self.__dict__.values():
            if type(v) is Var:
                out.append(v)
            elif kinds.get(type(v), 5):
                collect(v, out)
        return out

    def expr_list_vars(self: Any) -> list[Any]:
        """List the variables used by the expression (numba's ``Expr.list_vars``)."""
        if type(self)._rec_list_vars is not rec_list_vars:
            return self._rec_list_vars(self._kws)
        out: list[Any] = []
        for v in self._kws.values():
            if type(v) is Var:
                out.append(v)
            elif kinds.get(type(v), 5):
                collect(v, out)
        return out

    ir.Inst._rec_list_vars = rec_list_vars
    ir.Stmt.list_vars = stmt_list_vars
    ir.Expr.list_vars = expr_list_vars
    ir.Inst._dynslam2d_fast = True
    return True


def _gather(blocks: Any, cfg: Any, ssa: Any, ir: Any, cache_list_vars: Any) -> tuple[Any, dict[Any, set[str]], bool]:
    """numba's ``_find_defs_violators`` (the same violators in the same order), plus the names each block holds
    (targets and every variable of its statements: ``Stmt.list_vars``) and whether the pass could see an IR object
    twice: a statement, an assigned instruction, an instruction nested in either, or an ``Expr``'s keyword dict
    reached from two places (numba's handlers rewrite a statement by copying it and mutating the copy's keyword dict,
    which the copy shares with the original; with such sharing that would change a statement still in the IR), or
    a statement of a type whose rewrite other code registered (``ir_utils.visit_vars_extensions``: numba's parfors).

    An ``ir.Assign`` with numba's three attributes (value, target, location: ``list_vars`` lists the value's variables
    then the target) takes its value's variables from ``cache_list_vars`` (``_FixSSAVars`` looks them up there), and
    another statement its own: the same lists numba's ``_GatherDefsHandler`` builds, computed once."""
    from numba.core import ir_utils

    Assign, Inst, Expr, Var = ir.Assign, ir.Inst, ir.Expr, ir.Var
    plain = (ir.Const, ir.Global, ir.FreeVar, ir.Arg)  # values without variables (numba's _rec_list_vars: [])
    defs: Any = defaultdict(list)
    uses: Any = defaultdict(set)
    names: dict[Any, set[str]] = {}
    seen: set[int] = set()
    shared = [False]
    extensions = tuple(ir_utils.visit_vars_extensions)  # statement types rewritten by other code (numba's parfors)
    nested = (Inst, list, tuple, dict)
    get = cache_list_vars.get

    def walk(val: Any) -> None:  # every instruction and keyword dict reachable as _rec_list_vars reaches them
        if isinstance(val, Inst):
            if id(val) in seen:
                shared[0] = True
            seen.add(id(val))
            if isinstance(val, Expr):
                if id(val._kws) in seen:
                    shared[0] = True
                seen.add(id(val._kws))
                val = val._kws
            else:
                val = val.__dict__
        for v in val.values() if isinstance(val, dict) else val:
            if type(v) is not Var and isinstance(v, nested):
                walk(v)

    for label, blk in blocks.items():
        held = names[label] = set()
        for stmt in blk.body:
            value = getattr(stmt, "value", None)
            if type(stmt) is Assign and len(stmt.__dict__) == 3 and (isinstance(value, (Inst, Var))
                                                                     or type(value) in plain):
                if id(stmt) in seen:
                    shared[0] = True
                seen.add(id(stmt))
                target = stmt.target.name
                defs[target].append((stmt, label))  # numba's _GatherDefsHandler.on_assign from here
                held.add(target)
                if isinstance(value, Inst):
                    walk(value)
                    for var in get(value):
                        k = var.name
                        held.add(k)
                        if k != target:
                            uses[k].add(label)
                elif isinstance(value, Var):
                    k = value.name
                    held.add(k)
                    if k != target:
                        uses[k].add(label)
                continue
            walk(stmt)
            if extensions and isinstance(stmt, extensions):
                shared[0] = True
            if isinstance(stmt, Assign):  # numba's _GatherDefsHandler
                target = stmt.target.name
                defs[target].append((stmt, label))
                held.add(target)
                for var in stmt.list_vars():
                    k = var.name
                    held.add(k)
                    if k != target:
                        uses[k].add(label)
            else:
                for var in get(stmt):
                    k = var.name
                    held.add(k)
                    uses[k].add(label)
    # numba's _find_defs_violators from here
    violators = ssa.OrderedSet([k for k, vs in defs.items() if len(vs) > 1])
    doms = cfg.dominators()
    for k, use_blocks in uses.items():
        if k not in violators:
            for label in use_blocks:
                dom = doms[label]
                def_labels = {label for _assign, label in defs[k]}
                if not def_labels.intersection(dom):
                    violators.add(k)
                    break
    return violators, names, shared[0]


def sparse_ssa() -> bool:
    """Replace ``numba.core.ssa._run_ssa`` (which ``reconstruct_ssa`` calls) with :func:`sparse_run_ssa`, when numba's
    sources are those checked (:data:`SOURCES`). Returns whether it changed numba (not when called again)."""
    from numba.core import ssa

    if getattr(ssa._run_ssa, "_dynslam2d_sparse", False) or not _sources_checked():
        return False
    original = ssa._run_ssa

    def run_ssa(blocks: Any) -> Any:
        """Run SSA reconstruction on IR blocks of a function (numba's, visiting only the statements that hold each
        violator: :func:`sparse_run_ssa`)."""
        return sparse_run_ssa(blocks, original)

    run_ssa._dynslam2d_sparse = True  # type: ignore[attr-defined]
    run_ssa._dynslam2d_original = original  # type: ignore[attr-defined]
    ssa._run_ssa = run_ssa
    return True


def sparse_run_ssa(blocks: Any, original: Any) -> Any:
    """numba's ``ssa._run_ssa`` (SSA reconstruction of a function's blocks, Choi et al.), running each violator's two
    rewrite passes on the statements that hold its name only.

    numba's ``_fresh_vars`` pass changes only the assignments to the violator, and its ``_fix_ssa_vars`` pass only
    the statements whose variables (``list_vars``, remembered per object in ``_CacheListVars``) include it; every other
    statement comes out as the same object, with no change to the pass's state (definition map, phi map, the scope's
    names, warnings). So only the statements holding the violator's name (a superset: each statement's names when
    first looked at, plus the names given to the violators rewritten since), in the blocks holding it, go through
    numba's own handlers, in numba's order and with numba's state; each block numba's pass would rebuild is a new
    ``ir.Block`` with the handlers' statements, phi nodes are prepended as numba does, and at the end every block is
    a new ``ir.Block``, as after numba's last pass. The variable lists numba remembers are those of objects still in
    the IR, which do not change while they are: remembered later (only for the statements looked at) they are the
    same. That holds when no IR object is reachable from two places (:func:`_gather`); otherwise, when numba's ssa
    logger logs DEBUG, and for a function without blocks, numba's ``original`` runs."""
    import logging

    from numba.core import ir, ssa
    from numba.core.analysis import compute_cfg_from_blocks

    if not blocks or ssa._logger.isEnabledFor(logging.DEBUG):
        return original(blocks)
    cfg = compute_cfg_from_blocks(blocks)
    cache_list_vars = ssa._CacheListVars()
    violators, names, shared = _gather(blocks, cfg, ssa, ir, cache_list_vars)
    if shared:
        FALLBACKS[0] += 1
        return original(blocks)
    df_plus = ssa._iterated_domfronts(cfg)
    current = dict(blocks)
    held: dict[Any, list[set[str]]] = {}  # label -> the names of each statement of its current block
    made: set[Any] = set()  # labels whose current block was made here (never one of the caller's blocks)
    Assign, Block = ir.Assign, ir.Block
    for varname in violators:
        labels = [label for label in current if varname in names[label]]
        for label in labels:
            if label not in held:
                held[label] = _statement_names(current[label].body, cache_list_vars, Assign, ir.Inst, ir.Var)
        scope = next(iter(current.values())).scope  # numba's _get_scope: the first block's
        # _fresh_vars: fresh names for the assignments to ``varname``
        states: dict[str, Any] = {"scope": scope, "varname": varname}
        states["defmap"] = defmap = defaultdict(list)
        changed = _rewrite(current, labels, held, states, ssa._FreshVarHandler(), Assign, Block)
        # _fix_ssa_vars: each use gets its reaching definition, phi nodes where needed
        states = {"scope": scope, "varname": varname, "defmap": defmap}
        states["phimap"] = phimap = defaultdict(list)
        states["cfg"] = cfg
        states["phi_locations"] = ssa._compute_phi_locations(df_plus, defmap)
        changed += _rewrite(current, labels, held, states, ssa._FixSSAVars(cache_list_vars), Assign, Block)
        made.update(labels)
        fresh = {assign.target.name for stmts in defmap.values() for assign in stmts}  # with the phi nodes'
        for label, i in changed:
            held[label][i] |= fresh
            names[label] |= fresh
        for label, philist in phimap.items():
            curblk = current[label]
            if label not in made:
                old, curblk = curblk, Block(scope=curblk.scope, loc=curblk.loc)
                curblk.body = old.body
                current[label] = curblk
                made.add(label)
            curblk.body = philist + curblk.body
            names[label] |= fresh
            if label in held:
                held[label] = [set(fresh) for _ in philist] + held[label]
    if violators:
        for label, blk in current.items():
            if label not in made:
                new = current[label] = Block(scope=blk.scope, loc=blk.loc)
                new.body = list(blk.body)
        blocks = current
    # Post-condition checks (numba's). CFG invariant
    cfg_post = compute_cfg_from_blocks(blocks)
    if cfg_post != cfg:
        from numba.core import errors

        raise errors.CompilerError("CFG mutated in SSA pass")
    return blocks


def _statement_names(body: list[Any], cache_list_vars: Any, Assign: type, Inst: type, Var: type) -> list[set[str]]:
    """The names numba's SSA handlers see in each statement of ``body``: an assignment's target and the variables of
    its value (remembered in numba's ``cache_list_vars`` as ``_FixSSAVars`` does), another statement's variables."""
    out = []
    get = cache_list_vars.get
    for stmt in body:
        if isinstance(stmt, Assign):
            value = stmt.value
            if isinstance(value, Inst):
                seen = {var.name for var in get(value)}
            elif isinstance(value, Var):
                seen = {value.name}
            else:
                seen = set()
            seen.add(stmt.target.name)
        else:
            seen = {var.name for var in get(stmt)}
        out.append(seen)
    return out


def _rewrite(current: dict[Any, Any], labels: list[Any], held: dict[Any, list[set[str]]], states: dict[str, Any],
             handler: Any, Assign: type, Block: Any) -> list[tuple[Any, int]]:
    """numba's ``_run_block_rewrite`` and ``_run_ssa_block_pass`` on the blocks ``labels`` of ``current`` (each
    replaced by a new block), calling ``handler`` on the statements whose names (``held``) include the violator only
    (the others come out of numba's handlers as they are). Returns the (label, index) of each statement replaced."""
    varname = states["varname"]
    changed = []
    for label in labels:
        blk = current[label]
        newbody = list(blk.body)
        states["label"] = label
        states["block"] = blk
        for i, seen in enumerate(held[label]):
            if varname in seen:
                stmt = newbody[i]
                if isinstance(stmt, Assign):
                    ret = handler.on_assign(states, stmt)
                else:
                    ret = handler.on_other(states, stmt)
                assert ret is not None
                if ret is not stmt:
                    newbody[i] = ret
                    changed.append((label, i))
        newblk = Block(scope=blk.scope, loc=blk.loc)
        newblk.body = newbody
        current[label] = newblk
    return changed


def _swap_code(name: str, params: str, impl: Any) -> bool:
    """Have numba's ``analysis.<name>`` run ``impl``: the function object keeps its identity (modules imported it by
    name) and its code becomes a call of ``analysis._dynslam2d_<name>`` (= ``impl``); numba's own stays reachable as
    its ``__wrapped__`` (for tests and benchmarks/check_jitssa.py). Returns whether it changed numba."""
    from numba.core import analysis

    func = getattr(analysis, name)
    space: dict[str, Any] = {}
    exec(compile(f"def {name}({params}):\n    return _dynslam2d_{name}({params})\n", analysis.__file__, "exec"),
         space)
    code = space[name].__code__
    if code.co_freevars != func.__code__.co_freevars or code.co_argcount != func.__code__.co_argcount:
        return False
    setattr(analysis, f"_dynslam2d_{name}", impl)
    func.__wrapped__ = type(func)(func.__code__, vars(analysis), name)
    func.__code__ = code
    return True


def lean_use_defs() -> bool:
    """Have numba's ``analysis.compute_use_defs`` (each block's used and defined variable names; about 1200 calls on
    a cold run of the README's first command, most from ``postproc.PostProcessor``) list an ``ir.Assign``'s
    variables once instead of twice.

    numba lists the assigned value's variables (to see whether the target is among them) and then the whole
    statement's (value's variables, then the target: ``Stmt.list_vars`` over the assignment's attributes in their
    order). For an assignment with numba's three attributes the statement's list is the value's list (``list_vars``
    of an instruction, ``[value]`` of a variable, empty for a constant, global, free variable or argument) plus the
    target, so it is built from the first; any other statement is listed as numba does. The same sets, filled in
    the same order (:func:`fast_compute_use_defs`). Swapped in by :func:`_swap_code`. Done only when numba's sources
    are those checked (:data:`SOURCES`). Returns whether it changed numba (not when called again)."""
    from numba.core import analysis

    if hasattr(analysis, "_dynslam2d_compute_use_defs") or not _sources_checked():
        return False
    return _swap_code("compute_use_defs", "blocks", fast_compute_use_defs)


def bit_live_map() -> bool:
    """Have numba's ``analysis.compute_live_map`` (the variables live at each block's entry; called with
    ``compute_use_defs`` by every ``PostProcessor.run`` and dead-code removal) run its two fixed points over bit
    masks instead of Python sets of names (:func:`fast_compute_live_map`, pass cold36). Swapped in by
    :func:`_swap_code`. Done only when numba's sources are those checked (:data:`SOURCES`). Returns whether it
    changed numba (not when called again)."""
    from numba.core import analysis

    if hasattr(analysis, "_dynslam2d_compute_live_map") or not _sources_checked():
        return False
    return _swap_code("compute_live_map", "cfg, blocks, var_use_map, var_def_map", fast_compute_live_map)


def fast_compute_use_defs(blocks: Any) -> Any:
    """numba's ``analysis.compute_use_defs(blocks)`` (block label -> set of variable names used before any definition
    in the block, and -> set of names defined), each ``ir.Assign`` with numba's three attributes listed once
    (:func:`lean_use_defs`)."""
    from numba.core import analysis, ir

    extensions = analysis.ir_extension_usedefs
    Assign, Inst, Var, Loc = ir.Assign, ir.Inst, ir.Var, ir.Loc
    plain = (ir.Arg, ir.Const, ir.Global, ir.FreeVar)
    listed = Assign.list_vars is ir.Stmt.list_vars and Assign._rec_list_vars is ir.Inst._rec_list_vars
    var_use_map = {}  # { block offset -> set of vars }
    var_def_map = {}  # { block offset -> set of vars }
    for offset, ir_block in blocks.items():
        var_use_map[offset] = use_set = set()
        var_def_map[offset] = def_set = set()
        for stmt in ir_block.body:
            if type(stmt) in extensions:
                func = extensions[type(stmt)]
                func(stmt, use_set, def_set)
                continue
            if isinstance(stmt, Assign):
                value = stmt.value
                if isinstance(value, Inst):
                    value_vars = value.list_vars()
                    rhs_set: Any = {var.name for var in value_vars}
                elif isinstance(value, Var):
                    value_vars = [value]
                    rhs_set = {value.name}
                elif isinstance(value, plain):
                    value_vars = []
                    rhs_set = ()
                else:
                    raise AssertionError('unreachable', type(value))
                target = stmt.target
                # If lhs not in rhs of the assignment
                if target.name not in rhs_set:
                    def_set.add(target.name)
                if (listed and type(stmt) is Assign and len(stmt.__dict__) == 3 and type(target) is Var
                        and type(stmt.loc) is Loc):
                    for var in value_vars:
                        # do not include locally defined vars to use-map
                        if var.name not in def_set:
                            use_set.add(var.name)
                    if target.name not in def_set:
                        use_set.add(target.name)
                    continue
            for var in stmt.list_vars():
                # do not include locally defined vars to use-map
                if var.name not in def_set:
                    use_set.add(var.name)
    return analysis._use_defs_result(usemap=var_use_map, defmap=var_def_map)


def fast_compute_live_map(cfg: Any, blocks: Any, var_use_map: Any, var_def_map: Any) -> dict[Any, set[str]]:
    """numba's ``analysis.compute_live_map`` (0.68) with each block's variable sets as bits of one Python int.

    The same two least fixed points: the variables defined or used on some path to each block's entry ("def
    reach": a block's own uses and definitions, propagated to its successors in topological order), then the
    variables live at each block's entry (its uses, plus what is live at a successor's entry, reachable at the
    block and not defined in it, propagated backwards); each loop runs until no set grows, as numba's does. Returns
    ``{block: set of names}`` for every block of ``blocks``, each set starting from the block's use set as numba's."""
    topo_order = cfg.topo_order()
    bit: dict[str, int] = {}
    names: list[str] = []

    def mask(vars_: Any) -> int:
        m = 0
        for name in vars_:
            b = bit.get(name)
            if b is None:
                b = bit[name] = 1 << len(names)
                names.append(name)
            m |= b
        return m

    use = {o: mask(s) for o, s in var_use_map.items()}
    dfn = {o: mask(s) for o, s in var_def_map.items()}
    succs = {o: [d for d, _ in cfg.successors(o)] for o in topo_order}
    reach: dict[Any, int] = {}
    changed = True
    while changed:  # numba's def_reach, to its fixed point
        changed = False
        for o in topo_order:
            old = reach.get(o, 0)
            r = old | dfn[o] | use[o]
            if r != old:
                reach[o] = r
                changed = True
            for d in succs[o]:
                before = reach.get(d, 0)
                after = before | r
                if after != before:
                    reach[d] = after
                    changed = True
    live = {o: use[o] for o in blocks.keys()}
    preds = {o: [p for p, _ in cfg.predecessors(o)] for o in topo_order}
    order = topo_order[::-1]
    changed = True
    while changed:  # numba's liveness, to its fixed point
        changed = False
        for o in order:
            here = live[o]
            for p in preds[o]:
                before = live[p]
                after = before | (here & reach.get(p, 0) & ~dfn[p])
                if after != before:
                    live[p] = after
                    changed = True
                    if p == o:
                        here = after
    live_map = {}
    for o in blocks.keys():
        found = set(var_use_map[o])
        extra = live[o] & ~use[o]
        while extra:
            low = extra & -extra
            found.add(names[low.bit_length() - 1])
            extra ^= low
        live_map[o] = found
    return live_map


def _postproc_checked() -> bool:
    """Whether numba's ``postproc.py`` and ``transforms.py`` have the SHA-256 in :data:`POSTPROC_SOURCES`."""
    key = tuple(sorted(POSTPROC_SOURCES.items()))
    if key not in _CHECKED:
        try:
            from numba.core import postproc, transforms

            _CHECKED[key] = all(
                hashlib.sha256(Path(module.__file__).read_bytes()).hexdigest()[:16] == POSTPROC_SOURCES[name]
                for name, module in (("postproc", postproc), ("transforms", transforms)))
        except (ImportError, OSError, TypeError):  # pragma: no cover - numba is a dependency
            _CHECKED[key] = False
    return _CHECKED[key]


def shared_cfg() -> bool:
    """Have numba's ``postproc.PostProcessor.run`` (after every rewrite, inlining and legalisation pass: about 1100
    calls on a cold run of the README's first command) build the function's control-flow graph once instead of twice
    (:func:`shared_cfg_run`). Done only when numba's ``postproc.py`` and ``transforms.py`` are those checked
    (:data:`POSTPROC_SOURCES`). Returns whether it changed numba (not when called again)."""
    from numba.core import postproc, transforms

    run = postproc.PostProcessor.run
    if getattr(run, "_dynslam2d_shared_cfg", False) or not _postproc_checked():
        return False
    expected = transforms.canonicalize_cfg, transforms.canonicalize_cfg_single_backedge

    def lean_run(self: Any, emit_dels: bool = False, extend_lifetimes: bool = False) -> None:
        """numba's ``PostProcessor.run`` (canonical CFG, variable lifetimes, block entry variables, generator info,
        ``del`` statements), the canonicalisation's control-flow graph reused (:func:`shared_cfg_run`)."""
        if (transforms.canonicalize_cfg, transforms.canonicalize_cfg_single_backedge) != expected:  # replaced since
            return run(self, emit_dels=emit_dels, extend_lifetimes=extend_lifetimes)
        return shared_cfg_run(self, emit_dels, extend_lifetimes)

    lean_run._dynslam2d_shared_cfg = True  # type: ignore[attr-defined]
    lean_run.__wrapped__ = run  # type: ignore[attr-defined]
    postproc.PostProcessor.run = lean_run
    return True


def canonical_blocks(blocks: Any) -> tuple[Any, Any]:
    """numba's ``transforms.canonicalize_cfg(blocks)`` (a new dict of the blocks, each loop with several back edges
    given one tail block), plus the control-flow graph it built of ``blocks`` when it rewrote no loop, else None.

    numba builds ``compute_cfg_from_blocks(blocks)``, copies the dict and rewrites the loops with more than one back
    edge (checked on the original blocks' terminators). With no such loop the copy is returned as it is: the same
    blocks in the same order, so the graph of the copy that ``VariableLifetime.cfg`` would build next is this one's
    equal (nodes and edges added in the same order; its lazily computed loops and back edges are functions of the
    graph). With such a loop numba's own function runs (its graph differs from the rewritten blocks')."""
    from numba.core import analysis, transforms

    cfg = analysis.compute_cfg_from_blocks(blocks)
    for loop in cfg.loops().values():  # numba's has_multiple_backedges
        count = 0
        for k in loop.body:
            if loop.header in blocks[k].terminator.get_targets():
                count += 1
        if count > 1:
            return transforms.canonicalize_cfg(blocks), None
    return blocks.copy(), cfg


def shared_cfg_run(self: Any, emit_dels: bool = False, extend_lifetimes: bool = False) -> None:
    """numba 0.68's ``PostProcessor.run`` (``postproc.py``), statement for statement, with the control-flow graph of
    :func:`canonical_blocks` given to the ``VariableLifetime`` (its ``cfg``, which numba would build again from the
    same blocks right away) when the canonicalisation rewrote nothing; with :func:`lazy_lifetimes` installed it stops
    after installing the ``VariableLifetime`` where nothing reads what the rest computes."""
    from numba.core import analysis, postproc

    blocks, cfg = canonical_blocks(self.func_ir.blocks)
    self.func_ir.blocks = blocks
    vlt = postproc.VariableLifetime(self.func_ir.blocks)
    if cfg is not None:
        vlt.__dict__["cfg"] = cfg  # functools.cached_property's slot: VariableLifetime.cfg returns it
    self.func_ir.variable_lifetime = vlt
    if _LIFETIMES_LAZY[0] and not emit_dels and not self.func_ir.is_generator and not _UNROLLING[0]:
        self.func_ir.generator_info = None  # (numba's, for a function that is no generator)
        return  # the analyses left to the VariableLifetime's cached properties: see lazy_lifetimes

    bev = analysis.compute_live_variables(vlt.cfg, self.func_ir.blocks,
                                          vlt.usedefs.defmap,
                                          vlt.deadmaps.combined)
    for offset, ir_block in self.func_ir.blocks.items():
        self.func_ir.block_entry_vars[ir_block] = bev[offset]

    if self.func_ir.is_generator:
        self.func_ir.generator_info = postproc.GeneratorInfo()
        self._compute_generator_info()
    else:
        self.func_ir.generator_info = None

    # Emit del nodes, do this last as the generator info parsing generates
    # and then strips dels as part of its analysis.
    if emit_dels:
        self._insert_var_dels(extend_lifetimes=extend_lifetimes)


#: Whether :func:`shared_cfg_run` leaves a function's variable lifetimes to be computed when read (set by
#: :func:`lazy_lifetimes`), and whether numba's ``literal_unroll`` pass is transforming a function (its runs eager).
_LIFETIMES_LAZY = [False]
_UNROLLING = [0]

#: SHA-256 (first 16 hex digits) of the numba 0.68.1 files read to establish what :func:`lazy_lifetimes` relies on:
#: who reads ``FunctionIR.variable_lifetime`` and ``block_entry_vars`` (``untyped_passes.py``: ``literal_unroll``;
#: ``transforms.py`` and ``withcontexts.py``: loop and with-lifting; ``pylowering.py``: object mode; ``ir.py``).
LAZY_SOURCES = {"untyped_passes": "2f1ab65c656a235e", "withcontexts": "6350053b3e42a8f5",
                "pylowering": "3893331f00aeb23d"}


def _lazy_checked() -> bool:
    """Whether numba's files have the SHA-256 in :data:`LAZY_SOURCES` and :data:`POSTPROC_SOURCES`."""
    key = tuple(sorted(LAZY_SOURCES.items()))
    if key not in _CHECKED:
        try:
            from numba.core import pylowering, untyped_passes, withcontexts

            files = {"untyped_passes": untyped_passes, "withcontexts": withcontexts, "pylowering": pylowering}
            _CHECKED[key] = all(hashlib.sha256(Path(files[name].__file__).read_bytes()).hexdigest()[:16] == digest
                                for name, digest in LAZY_SOURCES.items())
        except (ImportError, OSError, TypeError):  # pragma: no cover - numba is a dependency
            _CHECKED[key] = False
    return _CHECKED[key] and _postproc_checked()


def _unrolls(func_ir: Any) -> bool:
    """Whether ``func_ir`` assigns numba's ``literal_unroll`` (a global or free variable): numba's own test at the
    start of its ``literal_unroll`` pass (``LiteralUnroll.run_pass``), which transforms nothing otherwise."""
    from numba.core import ir
    from numba.misc.special import literal_unroll

    for block in func_ir.blocks.values():
        for stmt in block.find_insts(ir.Assign):
            if isinstance(stmt.value, (ir.Global, ir.FreeVar)) and stmt.value.value is literal_unroll:
                return True
    return False


def lazy_lifetimes() -> bool:
    """Have :func:`shared_cfg_run` (numba's ``PostProcessor.run``, ≈ 1 100 calls on a cold run of the README's first
    command, after every pass that changes a function's IR) leave the function's variable lifetimes to numba's own
    lazy ``VariableLifetime`` instead of computing them all each time (pass cmp70).

    numba's ``run`` builds a ``VariableLifetime`` (its ``cfg``, ``usedefs``, ``livemap`` and ``deadmaps`` are cached
    properties, computed when first read) and then reads them all at once to fill ``FunctionIR.block_entry_vars``
    (``analysis.compute_live_variables``): ≈ 2.5 s of one core's CPU on that run, and the next ``run`` replaces the
    lot. ``block_entry_vars`` is read only by object-mode lowering (``pylowering.py``) and for generators (``run``
    itself); ``deadmaps`` only by ``run`` (``block_entry_vars``, ``del`` statements); the ``livemap`` only by loop
    lifting (object mode), with-lifting (right after a ``run`` of its own: nothing changed in between, the same
    sets) and the ``literal_unroll`` pass, which changes statements before it reads it. So ``run`` now stops after
    installing the ``VariableLifetime`` (control-flow graph as :func:`shared_cfg_run` has it) when it emits no
    ``del`` statements, the function is no generator and no ``literal_unroll`` pass is running (its ``run`` calls are
    numba's, and the lifetimes of the IR it starts from are computed when it starts: the same IR as at the last
    ``run``). The command line's processes compile no kernel in object mode (``njit`` only; ``tests/test_jitssa.py``
    checks the kernel modules hold no ``objmode``, ``forceobj``, ``literal_unroll`` or generator kernel). The
    compiled code is the same (``benchmarks/check_jitprint.py --dump D --asm``: every library's assembly). Returns
    whether it changed numba (not when called again; not with other ``postproc.py`` / ``transforms.py`` sources)."""
    from numba.core import untyped_passes

    if _LIFETIMES_LAZY[0] or not _lazy_checked():
        return False
    unroll = untyped_passes.LiteralUnroll.run_pass

    def eager_unroll(self: Any, state: Any) -> Any:
        if not _unrolls(state.func_ir):
            return unroll(self, state)  # (returns at once: nothing to unroll)
        vlt = getattr(state.func_ir, "variable_lifetime", None)
        if vlt is not None:  # what numba's run computed when it ran: the IR is as that run left it
            vlt.deadmaps  # noqa: B018 - cached property: usedefs, livemap, deadmaps computed now
        _UNROLLING[0] += 1
        try:
            return unroll(self, state)
        finally:
            _UNROLLING[0] -= 1

    eager_unroll.__wrapped__ = unroll  # type: ignore[attr-defined]
    untyped_passes.LiteralUnroll.run_pass = eager_unroll
    _LIFETIMES_LAZY[0] = True
    return True


def install() -> bool:
    """Install :func:`fast_list_vars`, :func:`lean_use_defs`, :func:`bit_live_map`, :func:`sparse_ssa` (numba's
    sources checked), :func:`shared_cfg` and :func:`lazy_lifetimes`; returns whether any was installed. Called by
    :func:`dynslam2d.jitcache.lean_numba_compile` at the first compile."""
    done = [fast_list_vars(), lean_use_defs(), bit_live_map(), sparse_ssa(), shared_cfg()]
    done.append(done[-1] and lazy_lifetimes())
    return any(done)
