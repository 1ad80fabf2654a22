"""The one place that initialises Taichi.

The library never calls ``ti.init`` on import: entry points (the CLI, demos, benchmarks, the
pytest fixture) call :func:`init` once.  Kernels compiled by the solver are cached on disk by
Taichi's offline cache so that a second run of the CLI skips most of the compile time.
"""
import functools
import os
import types

import taichi as ti
from taichi.lang import kernel_impl as _kernel_impl
from taichi.lang.ast import ast_transformer_utils as _ast_utils

ARCHES = ("cpu", "cuda", "vulkan", "metal", "opengl", "gpu", "auto")

_state = {"arch": None, "threads": None, "kwargs": None}

#: Memory order of a ``(H, W, c_max)`` volume that is read at a disparity per pixel (the
#: Eq. 2 step's matching costs, B at Theta_1): rows, then disparities, then columns, so that
#: neighbours along a row at the same disparity are neighbours in memory.  Indexing stays
#: ``[y, x, c - 1]``.  At 760x340x50 an iteration took 34.6 -> 29.0 ms on the 2-core CPU.
ROWS_DISPARITIES_COLUMNS = (0, 2, 1)


def _resolve(arch: str):
    if arch == "auto":
        return ti.gpu if _gpu_available() else ti.cpu
    return getattr(ti, arch)


def _gpu_available() -> bool:
    # Taichi falls back to the CPU on its own when asked for ti.gpu without one; we only use
    # this to decide, so a missing GPU is never an error for arch="auto".
    return os.environ.get("CUDA_VISIBLE_DEVICES", "0") != ""


def _memoise_source_positions():
    """Build each of Taichi's source-position strings once per process.

    Taichi's front end formats a "File ..., line ..." string with the offending line and a
    caret line (two ``textwrap`` calls) for every AST node it visits, before it knows whether
    an error will need it, and it visits a node once per unrolled ``ti.static`` iteration and
    once per kernel that inlines its ``ti.func``.  A 760x340 solve visits ~79,000 nodes at
    ~6,000 distinct positions: ~2.5 s of every new solver's set-up (warm kernel cache) went
    into these strings.  The string depends only on the function's source and the node's
    position, so a cache returns Taichi's own text, unchanged (the kernels' debug info and
    the offline-cache keys stay the same).  Skipped if this Taichi has no such method.
    """
    context = getattr(_ast_utils, "ASTTransformerContext", None)
    build = getattr(context, "get_pos_info", None)
    if build is None or getattr(build, "_lss_memoised", False):
        return
    cache = {}

    def get_pos_info(self, node):
        key = (self.file, self.func.func, self.lineno_offset, self.indent,
               type(node).__name__, node.lineno, node.col_offset,
               getattr(node, "end_lineno", None), getattr(node, "end_col_offset", None))
        info = cache.get(key)
        if info is None:
            info = cache[key] = build(self, node)
        return info

    get_pos_info._lss_memoised = True
    get_pos_info.original = build
    context.get_pos_info = get_pos_info


class _MemoisedTextwrap:
    """The ``textwrap`` module as Taichi's kernel module sees it, with ``fill`` and
    ``dedent`` remembered per argument (both are pure functions of their arguments)."""

    def __init__(self, module):
        self._module = module
        self.fill = functools.lru_cache(maxsize=None)(module.fill)
        self.dedent = functools.lru_cache(maxsize=None)(module.dedent)

    def __getattr__(self, name):
        return getattr(self._module, name)


def _memoise_source_reading():
    """Read each kernel's and ``ti.func``'s source once per process.

    Before it parses a function, Taichi reads its source with ``inspect`` (which tokenises
    the file's lines to find the function's end) and re-wraps every line with
    ``textwrap.fill``, once per kernel instance and once per ``ti.func`` call site that it
    inlines: ~1,000 times in a 760x340 solve, 0.54 s of the front end's 1.6 s (warm kernel
    cache).  The source of a function does not change while the process runs, so the first
    answer is kept; Taichi still parses a fresh tree every time (it annotates the tree as it
    goes).  Skipped if this Taichi reads sources otherwise.
    """
    read = getattr(_kernel_impl, "getsourcelines", None)
    if read is None or getattr(read, "_lss_memoised", False):
        return
    lines = {}

    def getsourcelines(func):
        key = getattr(func, "__code__", func)
        found = lines.get(key)
        if found is None:
            found = lines[key] = read(func)
        return found

    getsourcelines._lss_memoised = True
    getsourcelines.original = read
    _kernel_impl.getsourcelines = getsourcelines
    if isinstance(getattr(_kernel_impl, "textwrap", None), types.ModuleType):
        _kernel_impl.textwrap = _MemoisedTextwrap(_kernel_impl.textwrap)


def init(arch: str | None = None, threads: int | None = None, offline_cache: bool = True,
         debug: bool = False) -> str:
    """Initialise Taichi once per process and return the arch name in use.

    Parameters
    ----------
    arch : {"cpu", "cuda", "vulkan", "metal", "opengl", "gpu", "auto"} or None
        Backend.  ``None`` keeps the current one if Taichi is initialised, else ``"cpu"``.
    threads : int or None
        CPU threads for the CPU backend (``None``: Taichi's default, all cores).
    offline_cache : bool
        Keep compiled kernels on disk between runs.

    Calling again with the same settings is a no-op; different settings re-initialise Taichi
    (every field allocated before becomes invalid, so do this before building a solver).
    """
    if arch is None:
        arch = _state["arch"] or "cpu"
    if arch not in ARCHES:
        raise ValueError(f"arch: expected one of {', '.join(ARCHES)}, got {arch!r}")
    if threads is not None and (not isinstance(threads, int) or threads < 1):
        raise ValueError(f"threads: expected a positive integer, got {threads!r}")
    if _state["arch"] == arch and _state["threads"] == threads:
        return arch
    kwargs = dict(arch=_resolve(arch), offline_cache=offline_cache, debug=debug,
                  default_fp=ti.f32, log_level=ti.WARN, random_seed=0,
                  unrolling_limit=0)
    if threads is not None:
        kwargs["cpu_max_num_threads"] = threads
    if kwargs["arch"] == ti.cpu:
        # Taichi's CFG passes (store forwarding, dead stores) are quadratic in the length of
        # a kernel's body and took ~half the compile time of the median's selection network
        # (4.6 -> 2.3 s), for no speed on the CPU: LLVM's own passes do the same there
        kwargs["cfg_optimization"] = False
    if arch in ("cuda", "vulkan", "metal", "opengl"):
        kwargs["enable_fallback"] = False
    _memoise_source_positions()
    _memoise_source_reading()
    try:
        ti.init(**kwargs)
    except RuntimeError as exc:
        _state["arch"] = _state["threads"] = _state["kwargs"] = None
        raise ValueError(f"arch: {arch!r} is not available on this machine "
                         f"({str(exc).splitlines()[0]})") from None
    _state["arch"], _state["threads"], _state["kwargs"] = arch, threads, kwargs
    return arch


def restart() -> None:
    """Start Taichi again with the settings of the last :func:`init`.

    Every field allocated before becomes invalid: close the solvers first.  Taichi numbers
    the SNodes of a process from 0 at ``ti.init`` and its offline cache keys kernels on those
    numbers, so a solver built after a restart finds the kernels that a fresh process
    compiled for its size, whatever was built before it in this process (``lss eval`` builds
    one solver per image size and search range).
    """
    if _state["kwargs"] is None:
        raise RuntimeError("backend.restart: Taichi was not initialised by backend.init")
    ti.init(**_state["kwargs"])


def ensure_init() -> str:
    """Initialise with the defaults if nobody has yet (used by the high-level API)."""
    if _state["arch"] is None:
        return init()
    return _state["arch"]


def current_arch() -> str | None:
    return _state["arch"]


def _bytes(dtype) -> int:
    """Size of one element of a Taichi primitive type."""
    for size, types in ((1, (ti.i8, ti.u8)), (2, (ti.i16, ti.u16)), (8, (ti.i64, ti.u64, ti.f64))):
        if dtype in types:
            return size
    return 4


@ti.kernel
def _zero_all(fields: ti.template()):
    for f in ti.static(fields):
        for I in ti.grouped(f):
            if ti.static(isinstance(f, ti.MatrixField)):
                f[I] = ti.Vector.zero(f.dtype, f.n)
            else:
                f[I] = ti.cast(0, f.dtype)


class FieldPool:
    """Allocates fields in SNode trees that can be freed as a whole.

    Plain ``ti.field(shape=...)`` allocations live until the process ends; a solver that is
    built once per image pair would leak them.  Classes take a pool, ask it for their fields,
    and the owner calls :meth:`finalize` once everything is declared and :meth:`destroy` when
    done.  Fields cannot be read or written before :meth:`finalize`.

    Two trees: the fields whose shape depends on the disparity range (``volume=True``: the
    cost volumes) and the rest, finalised first.  Taichi's offline cache keys a kernel on
    every tree it touches (shapes and SNode ids), so kernels that touch no volume -- the
    median, phi's derivatives, the upward and downward passes, the fit -- compile once per
    image size, whatever the disparity range, instead of once per (size, range).  The SNode
    ids count the nodes declared before in the process, which do not depend on the range.
    """

    def __init__(self):
        # created on first use: Taichi refuses to run while a builder is not finalised
        self._builders = [None, None]
        self._trees = []
        self.nbytes = 0
        self.fields = []

    def _place(self, f, shape, offset, nbytes, order=None, volume=False):
        shape = tuple(int(s) for s in shape)
        if self._builders[int(volume)] is None:
            self._builders[int(volume)] = ti.FieldsBuilder()
        builder = self._builders[int(volume)]
        if shape and order is not None:
            node = builder
            for axis in order:
                node = node.dense(ti.axes(axis), shape[axis])
            node.place(f, offset=offset)
        elif shape:
            axes = ti.axes(*range(len(shape)))
            builder.dense(axes, shape).place(f, offset=offset)
        else:
            builder.place(f)
        n = 1
        for s in shape:
            n *= s
        self.nbytes += n * nbytes
        self.fields.append(f)
        return f

    def field(self, dtype, shape, offset=None, order=None, volume=False):
        """A scalar field; ``order``: its axes from the outermost to the innermost in memory
        (default: as indexed, the last axis innermost); ``volume``: its shape depends on the
        disparity range (see the class)."""
        return self._place(ti.field(dtype), shape, offset, _bytes(dtype), order, volume)

    def vector(self, n, dtype, shape, offset=None):
        return self._place(ti.Vector.field(n, dtype), shape, offset, n * _bytes(dtype))

    def finalize(self):
        self._trees = [b.finalize() for b in self._builders if b is not None]
        return self

    def zero(self):
        """Set every field to 0, the state of a freshly finalised pool (one kernel for all
        of them: ``fill`` would compile one per field)."""
        _zero_all(tuple(self.fields))

    def destroy(self):
        for tree in self._trees:
            tree.destroy()
        self._trees = []
