"""The one place that initialises Taichi: entry points (the CLI, demos, benchmarks, the pytest
fixture) call :func:`init` once; the library never calls ``ti.init`` on import.  Taichi's
offline cache keeps compiled kernels on disk, so a second run skips most of the compiling.
"""
import gc
import os
import sys
import weakref

import numpy as np
import taichi as ti
from . import taichi_patches

ARCHES = ("cpu", "cuda", "vulkan", "metal", "opengl", "gpu", "auto")
#: What every command runs on unless told otherwise: CUDA if a device answers, else the CPU.
DEFAULT_ARCH = "auto"

_state = {"arch": None, "threads": None, "kwargs": None, "generation": 0, "reuse": True}
#: The library's SNode trees of the current Taichi that are not destroyed yet (pools, the
#: distance transforms' scratch): see :func:`fresh_numbering`.
_live = weakref.WeakSet()

#: Memory order of a ``(H, W, c_max)`` volume that is read at a disparity per pixel (the
#: Eq. 2 step's matching costs, B at Theta_1): rows, then disparities, then columns, so that
#: neighbours along a row at the same disparity are neighbours in memory.  Indexing stays
#: ``[y, x, c - 1]``.  At 760x340x50 this order saves about a sixth of an iteration on a
#: 2-core CPU.
ROWS_DISPARITIES_COLUMNS = (0, 2, 1)

#: GPU backends that ``"gpu"`` tries, in order.
GPU_ARCHES = ("cuda", "vulkan", "metal")

#: Taichi's offline cache limit (its 100 MB default drops the least recently used quarter
#: once a few image sizes' kernels outgrow it; a process then compiles for tens of seconds
#: what it loaded in a few).  ``TI_OFFLINE_CACHE_MAX_SIZE_OF_FILES`` (bytes) overrides it.
OFFLINE_CACHE_BYTES = 1 << 30

_probed = {}


def _library_present(arch: str) -> bool:
    """Whether the driver library of a GPU backend can be loaded at all (a cheap first test:
    without it, there is no device)."""
    import ctypes
    names = {"cuda": ("libcuda.so.1", "libcuda.so", "nvcuda.dll"),
             "vulkan": ("libvulkan.so.1", "libvulkan.so", "vulkan-1.dll"),
             "metal": ("/System/Library/Frameworks/Metal.framework/Metal",)}[arch]
    for name in names:
        try:
            ctypes.CDLL(name)
            return True
        except OSError:
            pass
    return False


def probe(arch: str, timeout: float = 60.0) -> tuple:
    """Whether Taichi can start on the GPU backend ``arch``, tried in a short subprocess
    (Taichi can crash the process that asks for a backend the machine lacks); the answer is
    kept for the process.  Returns ``(usable, reason)``."""
    if arch in _probed:
        return _probed[arch]
    if not _library_present(arch):
        answer = (False, f"no {arch} driver library")
    else:
        import subprocess
        code = (f"import taichi as ti; ti.init(arch=ti.{arch}, enable_fallback=False, "
                f"offline_cache=False, log_level=ti.ERROR)")
        env = dict(os.environ, ENABLE_TAICHI_HEADER_PRINT="0")
        try:
            run = subprocess.run([sys.executable, "-c", code], capture_output=True,
                                 text=True, timeout=timeout, env=env)
            lines = (run.stderr or "").strip().splitlines()
            answer = (run.returncode == 0,
                      "ok" if run.returncode == 0 else
                      (lines[-1] if lines else f"exit status {run.returncode}"))
        except subprocess.TimeoutExpired:
            answer = (False, f"no answer from a {arch} start-up in {timeout:g} s")
    _probed[arch] = answer
    return answer


def resolve(arch: str, log=None) -> str:
    """The concrete backend for ``arch``: ``"auto"`` is CUDA when a CUDA device answers, else
    the CPU (``log`` gets one line saying so); ``"gpu"`` is the first of
    :data:`GPU_ARCHES` that answers (``ValueError`` if none); any other name is itself."""
    if arch == "auto":
        usable, reason = probe("cuda")
        if usable:
            return "cuda"
        if log is not None:
            log(f"lss: no usable CUDA GPU ({reason}); running on the CPU")
        return "cpu"
    if arch == "gpu":
        reasons = []
        for candidate in GPU_ARCHES:
            usable, reason = probe(candidate)
            if usable:
                return candidate
            reasons.append(f"{candidate}: {reason}")
        raise ValueError(f"arch: 'gpu' found no usable GPU backend ({'; '.join(reasons)})")
    return arch


def init(arch: str | None = None, threads: int | None = None, offline_cache: bool = True,
         debug: bool = False, reuse_kernels: bool | None = None, kernel_profiler=None) -> str:
    """Initialise Taichi once per process; returns the backend in use (``"cpu"``, ...).

    Parameters
    ----------
    arch : {"cpu", "cuda", "vulkan", "metal", "opengl", "gpu", "auto"} or None
        Backend.  ``None`` keeps the current one if Taichi is initialised, else ``"cpu"``.
        ``"auto"``: CUDA when a device answers, else the CPU with one line on stderr;
        ``"gpu"``: the first GPU backend that answers (see :func:`resolve`); both probe in a
        subprocess, so a machine without a GPU never crashes the caller.
    threads : int or None
        CPU threads for the CPU backend (``None``: Taichi's default, all cores).
    offline_cache : bool
        Keep compiled kernels on disk between runs (up to :data:`OFFLINE_CACHE_BYTES`).
    reuse_kernels : bool or None
        Let every new solver start Taichi again first when none of the library's fields is
        alive (:func:`fresh_numbering`), so that it loads the kernels compiled for its size
        bucket from the offline cache; ``False`` if you keep Taichi fields of your own
        between solves.  ``None`` keeps the current setting (default ``True``).
    kernel_profiler : bool or None
        Time every kernel on the device (``ti.profiler``, ``demos/kernel_profile.py``; the
        kernels compile again under it).  ``None`` keeps the current setting (``False``).

    Calling again with the same settings is a no-op; different settings re-initialise Taichi
    (every field allocated before becomes invalid: do this before building a solver)."""
    arch = (_state["arch"] or "cpu") if arch is None else arch
    if arch not in ARCHES:
        raise ValueError(f"arch: expected one of {', '.join(ARCHES)}, got {arch!r}")
    if threads is not None and (not isinstance(threads, int) or threads < 1):
        raise ValueError(f"threads: expected a positive integer, got {threads!r}")
    if reuse_kernels is not None:
        _state["reuse"] = bool(reuse_kernels)
    arch = resolve(arch, log=lambda text: print(text, file=sys.stderr))
    on = bool((_state["kwargs"] or {}).get("kernel_profiler"))
    profiling = on if kernel_profiler is None else bool(kernel_profiler)
    if _state["arch"] == arch and _state["threads"] == threads and on == profiling:
        return arch
    kwargs = dict(arch=getattr(ti, arch), offline_cache=offline_cache, debug=debug,
                  default_fp=ti.f32, log_level=ti.WARN, random_seed=0,
                  unrolling_limit=0, kernel_profiler=profiling)
    if threads is not None:
        kwargs["cpu_max_num_threads"] = threads
    if offline_cache and not os.environ.get("TI_OFFLINE_CACHE_MAX_SIZE_OF_FILES"):
        kwargs["offline_cache_max_size_of_files"] = OFFLINE_CACHE_BYTES
    if kwargs["arch"] == ti.cpu:
        # Taichi's CFG passes (store forwarding, dead stores) are quadratic in the length of
        # a kernel's body and take about half the compile time of the median's selection
        # network, for no speed on the CPU: LLVM's own passes do the same there
        kwargs["cfg_optimization"] = False
        # nor do its "advanced" IR passes (whole-kernel CSE, loop-invariant motion, ...):
        # without them a kernel compiles in about 60 % of the time (a paper15 solve's 32:
        # about 15 s instead of 25 s on 2 cores), LLVM optimises what they would have, and
        # the iteration runs as fast; float results may differ in the last bits
        kwargs["advanced_optimization"] = False
    if arch != "cpu":
        kwargs["enable_fallback"] = False
    taichi_patches.install()
    try:
        ti.init(**kwargs)
    except RuntimeError as exc:
        _state["arch"] = _state["threads"] = _state["kwargs"] = None
        raise ValueError(f"arch: {arch!r} is not available on this machine "
                         f"({str(exc).splitlines()[0]})") from None
    _state["arch"], _state["threads"], _state["kwargs"] = arch, threads, kwargs
    _started()
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
    _started()


def _started():
    _state["generation"] += 1
    _live.clear()


def allocated(owner) -> int:
    """Record that ``owner`` (a pool, a scratch buffer) holds SNode trees of the current
    Taichi until it calls :func:`released`; returns the current :func:`generation`."""
    _live.add(owner)
    return _state["generation"]


def released(owner) -> None:
    _live.discard(owner)


def fresh_numbering() -> bool:
    """Start Taichi again before a new solver if fields were declared since it started and
    none of the library's is alive; returns whether it did.  The offline cache keys a kernel
    on its SNodes' ids, which count every node declared before in the process: so numbered
    as in a fresh process, a solver loads what any earlier solver of its bucket and
    parameters compiled (Taichi writes the cache when it restarts and at exit).  Not when
    ``init(reuse_kernels=False)`` or Taichi was started by someone else."""
    if (not _state["reuse"] or _state["kwargs"] is None
            or ti.lang.impl.get_runtime().prog.get_snode_tree_size() == 0):
        return False
    if _live:
        gc.collect()        # pools dropped without destroy() that only a cycle still holds
        if _live:
            return False
    restart()
    return True


def before_solver(arch: str | None = None) -> str:
    """What a new solver does first: :func:`init` with ``arch`` if given (else
    :func:`ensure_init`), then :func:`fresh_numbering`; returns the backend in use."""
    arch = init(arch=arch) if arch is not None else ensure_init()
    fresh_numbering()
    return arch


def generation() -> int:
    """How many times Taichi was started: trees of an earlier one must not be destroyed."""
    return _state["generation"]


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


@ti.func
def _element(f: ti.template(), offset: ti.template(), i):
    """The index of the ``i``-th element of ``f`` (1 to 3 axes) in row-major order
    (``offset``: the field's first index)."""
    shape = ti.static(f.shape)
    if ti.static(len(shape) == 1):
        return ti.Vector([i + offset[0]])
    elif ti.static(len(shape) == 2):
        return ti.Vector([i // shape[1] + offset[0], i % shape[1] + offset[1]])
    else:
        return ti.Vector([i // (shape[1] * shape[2]) + offset[0],
                          i // shape[2] % shape[1] + offset[1], i % shape[2] + offset[2]])


@ti.func
def _get(f: ti.template(), offset: ti.template(), i, out: ti.template()):
    """Element ``i`` (row-major) of ``f`` into row ``i`` of ``out``, as float64."""
    if ti.static(len(f.shape) == 0):
        if ti.static(isinstance(f, ti.MatrixField)):
            for c in ti.static(range(f.n)):
                out[i, c] = ti.cast(f[None][c], ti.f64)
        else:
            out[i, 0] = ti.cast(f[None], ti.f64)
    else:
        I = _element(f, offset, i)
        if ti.static(isinstance(f, ti.MatrixField)):
            for c in ti.static(range(f.n)):
                out[i, c] = ti.cast(f[I][c], ti.f64)
        else:
            out[i, 0] = ti.cast(f[I], ti.f64)


@ti.func
def _put(f: ti.template(), offset: ti.template(), i, src: ti.template()):
    """Row ``i`` of ``src`` into element ``i`` (row-major) of ``f``, cast to its type."""
    if ti.static(len(f.shape) == 0):
        if ti.static(isinstance(f, ti.MatrixField)):
            for c in ti.static(range(f.n)):
                f[None][c] = ti.cast(src[i, c], f.dtype)
        else:
            f[None] = ti.cast(src[i, 0], f.dtype)
    else:
        I = _element(f, offset, i)
        if ti.static(isinstance(f, ti.MatrixField)):
            for c in ti.static(range(f.n)):
                f[I][c] = ti.cast(src[i, c], f.dtype)
        else:
            f[I] = ti.cast(src[i, 0], f.dtype)


@ti.data_oriented
class _Transfer:
    """The two kernels that move the host's fields of a pool (and of its annexes) to or from
    the host: one loop over the elements of the field asked for, which branches to that
    field's copy (one parallel loop compiles in a fraction of the time of a loop per field).
    The fields are attributes read with ``ti.static``, not template arguments, which Taichi
    would hash at every launch."""

    def __init__(self, fields, offsets):
        self.fields, self.offsets = tuple(fields), tuple(offsets)

    @ti.kernel
    def read(self, which: ti.i32, n: ti.i32, out: ti.types.ndarray(dtype=ti.f64, ndim=2)):
        for i in range(n):
            for k in ti.static(range(len(self.fields))):
                if which == k:
                    _get(self.fields[k], self.offsets[k], i, out)

    @ti.kernel
    def write(self, which: ti.i32, n: ti.i32, src: ti.types.ndarray(dtype=ti.f64, ndim=2)):
        for i in range(n):
            for k in ti.static(range(len(self.fields))):
                if which == k:
                    _put(self.fields[k], self.offsets[k], i, src)


def _numpy_dtype(dtype):
    for np_type, types in ((np.float32, (ti.f32,)), (np.float64, (ti.f64,)),
                           (np.int32, (ti.i32,)), (np.int8, (ti.i8,)), (np.uint8, (ti.u8,)),
                           (np.int16, (ti.i16,)), (np.uint16, (ti.u16,)), (np.int64, (ti.i64,))):
        if dtype in types:
            return np_type
    raise TypeError(f"FieldPool: no host transfer for fields of {dtype}")


#: The smallest side of a size bucket, pixels (see :func:`bucket_size`).
BUCKET_MIN = 64


def bucket_size(n: int) -> int:
    """The side of the size bucket of an image side of ``n`` pixels: the smallest of 64, 96,
    128, 192, 256, 384, 512, 768, 1024, 1536, 2048, 3072, ... (powers of two and 1.5 times
    them, from :data:`BUCKET_MIN`) that holds ``n``.

    Two buckets per octave: a side is rounded up by at most 1.5x (65 -> 96; an area by at
    most 2.25x, about 1.4x on average), and 2000x1500 takes 2048x1536, 1.05x its area, where
    the next power of two (2048x2048) would take 1.4x, and up to 4x at other sizes.  Beyond
    1024x768 the median's sorted columns and medians take the bucket's shape too (32 bytes
    a bucket pixel, one set shared by a pool's 7x7 filters; below, the fixed shape of
    :data:`lss_kernels.kernels.median.SCRATCH`), as do the census's greys and words (24
    bytes for both views): ~0.25 GB at 2000x1500, against a solver's 4.8 GiB there with
    d_max 128.  Every bucket side is a multiple of 32: whole blocks of 8 lanes and tiles of
    4 windows.
    """
    n = int(n)
    if n < 1:
        raise ValueError(f"bucket_size: expected a positive side, got {n}")
    size = BUCKET_MIN
    while True:
        if n <= size:
            return size
        if n <= size * 3 // 2:
            return size * 3 // 2
        size *= 2


def bucket_shape(height: int, width: int) -> tuple:
    """``(bucket_size(height), bucket_size(width))``: the shape of the bucket-tree planes of
    an ``height x width`` image (see :class:`FieldPool`)."""
    return bucket_size(height), bucket_size(width)


class FieldPool:
    """Allocates fields in SNode trees that can be freed as a whole.

    Plain ``ti.field(shape=...)`` allocations live until the process ends; a solver that is
    built once per image pair would leak them.  Classes take a pool, ask it for their fields,
    and the owner calls :meth:`finalize` once everything is declared and :meth:`destroy` when
    done.  Fields cannot be read or written before :meth:`finalize`.

    Four trees, because Taichi's offline cache keys a kernel on every tree it touches
    (shapes and SNode ids):

    * the fields whose shape is the image's own size, finalised first (what the few kernels
      that keep one size's float code need, see :class:`Extent`);
    * the fields whose shape depends on the disparity range (``volume=True``: the cost
      volumes), so that kernels that touch no volume -- the median, phi's derivatives, the
      downward pass, the fit -- compile whatever the disparity range;
    * the *bucket* fields (``bucket=True``), whose shapes are those of the image's size
      bucket (:func:`bucket_shape`), so that kernels that touch only them (and volumes of
      the bucket's shape) and read the image's size at run time from an :class:`Extent` --
      most kernels of a solve -- compile once per bucket instead of once per size;
    * the *fixed* fields (``fixed=True``), whose shapes depend on nothing of the pair (the
      median's merge scratch), so that a kernel that touches only them and takes the size
      as arguments compiles once for every size and bucket.

    The SNode ids count the nodes declared before in the process, which depend neither on
    the range nor on the size.  An optional part of a solve (the refinement) takes an
    :meth:`annex`, whose trees come after the pool's: the pool's trees, and so the keys of
    the kernels that touch only them, are then the same with the part or without it.
    """

    def __init__(self):
        # created on first use: Taichi refuses to run while a builder is not finalised
        self._builders = [None] * 4     # the size, volume, bucket and fixed trees
        self._trees = []
        self._shared = {}
        self._loaders = []
        self._bytes = 0
        self.fields = []
        self._offsets = []
        self._host = []             # the fields that read and write move (see host)
        self._root = None           # the pool an annex belongs to
        self._io = None
        self.generation = None
        self._annexes = []

    @property
    def nbytes(self):
        """Bytes of the pool's fields and its annexes'."""
        return self._bytes + sum(a.nbytes for a in self._annexes)

    def annex(self):
        """A pool of its own trees that this pool finalises (after its own), zeroes and
        destroys with itself."""
        annex = FieldPool()
        annex._root = self
        self._annexes.append(annex)
        return annex

    def extent(self, height, width):
        """The pool's :class:`Extent` of ``height x width`` images (one per size, shared by
        every user of the pool); ask before :meth:`finalize`, which loads it."""
        return self.shared(("extent", int(height), int(width)),
                           lambda: Extent(self, height, width))

    def on_load(self, load):
        """Call ``load()`` once the pool is finalised and after every :meth:`zero`: it
        writes constants into fields (such as an :class:`Extent`'s size)."""
        self._loaders.append(load)

    def shared(self, key, make):
        """The object that ``make()`` returned when this pool was first asked for ``key``:
        fields (and their kernels) that several users of the pool share, one after the other
        -- scratch, such as the median's bucket fields, whose kernel then compiles once for
        all of them.  Ask before :meth:`finalize`."""
        if key not in self._shared:
            self._shared[key] = make()
        return self._shared[key]

    @staticmethod
    def _tree(volume, bucket, fixed=False):
        """The index of the tree of a field (checked before Taichi creates the field: one
        that is never placed stops every later kernel from compiling)."""
        if int(bool(volume)) + int(bool(bucket)) + int(bool(fixed)) > 1:
            raise ValueError("FieldPool: a field is in one of the volume, bucket and fixed "
                             "trees, not several")
        return 3 if fixed else 2 if bucket else int(bool(volume))

    def _place(self, f, shape, offset, nbytes, order, tree):
        shape = tuple(int(s) for s in shape)
        if self._builders[tree] is None:
            self._builders[tree] = ti.FieldsBuilder()
        builder = self._builders[tree]
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
        self._bytes += n * nbytes
        self.fields.append(f)
        self._offsets.append(tuple(offset) if offset is not None else (0,) * len(shape))
        return f

    def field(self, dtype, shape, offset=None, order=None, volume=False, bucket=False):
        """A scalar field; ``order``: its axes from the outermost to the innermost in memory
        (default: as indexed, the last axis innermost); ``volume``: its shape depends on the
        disparity range; ``bucket``: its shape is that of a size bucket (see the class)."""
        tree = self._tree(volume, bucket)
        return self._place(ti.field(dtype), shape, offset, _bytes(dtype), order, tree)

    def vector(self, n, dtype, shape, offset=None, bucket=False, fixed=False):
        """A field of ``n``-vectors; ``bucket`` as for :meth:`field`; ``fixed``: its shape
        depends on nothing of the pair (see the class)."""
        tree = self._tree(False, bucket, fixed)
        return self._place(ti.Vector.field(n, dtype), shape, offset, n * _bytes(dtype), None,
                           tree)

    def finalize(self):
        parts = (self, *self._annexes)
        for part in parts:          # every tree first: a kernel cannot run before
            part._trees = [b.finalize() for b in part._builders if b is not None]
            part.generation = allocated(part)
        for part in parts:
            for load in part._loaders:
                load()
        return self

    def zero(self):
        """Set every field to 0, the state of a freshly finalised pool (one kernel for all
        of them: ``fill`` would compile one per field); the extents keep their sizes."""
        _zero_all(tuple(self.fields))
        for load in self._loaders:
            load()
        for annex in self._annexes:
            annex.zero()

    def host(self, *fields):
        """Mark fields of this pool (or an annex) that the host reads or writes during a
        solve: :meth:`read` and :meth:`write` move them with one kernel each for all of
        them (``to_numpy`` and ``from_numpy`` compile one per field).  Mark them before
        :meth:`finalize` (whose loaders transfer): a field marked after the first transfer
        makes the pool compile its transfer kernels again."""
        root = self._root if self._root is not None else self
        for f in fields:
            self._host.append(f)
            if root._io is not None and id(f) not in root._io_index:
                root._io = None

    def _transfer(self):
        """The :class:`_Transfer` of this pool's host fields and its annexes' (one for all:
        made on first use, once every tree is finalised)."""
        if self._io is None:
            parts = (self, *self._annexes)
            fields, offsets = [], []
            for p in parts:
                for f, o in zip(p.fields, p._offsets):
                    if any(f is g for q in parts for g in q._host):
                        fields.append(f)
                        offsets.append(o)
            self._io = _Transfer(fields, offsets)
            self._io_index = {id(f): k for k, f in enumerate(fields)}
        return self._io

    def _index(self, f):
        """The transfer of ``f`` and its index there; ``(None, None)`` for a field of the
        pool that is not a host field."""
        root = self._root if self._root is not None else self
        io = root._transfer()
        k = root._io_index.get(id(f))
        if k is None:
            if not any(f is g for p in (root, *root._annexes) for g in p.fields):
                raise ValueError("FieldPool: the field is not one of this pool's")
            return None, None
        return io, k

    def read(self, f):
        """The whole of field ``f`` (this pool's or an annex's) as a numpy array of its
        shape (vector fields: one more axis) and dtype: through the pool's one read kernel
        for a :meth:`host` field, else Taichi's ``to_numpy``."""
        io, k = self._index(f)
        if io is None:
            return f.to_numpy()
        n = int(np.prod(f.shape, dtype=np.int64))
        m = f.n if isinstance(f, ti.MatrixField) else 1
        out = np.zeros((n, m), np.float64)
        io.read(k, n, out)
        shape = tuple(f.shape) + ((m,) if isinstance(f, ti.MatrixField) else ())
        return out.reshape(shape).astype(_numpy_dtype(f.dtype))

    def write(self, f, array):
        """Write ``array`` (``f``'s shape, vector fields with one more axis) into field
        ``f`` (this pool's or an annex's): through the pool's one write kernel for a
        :meth:`host` field, else Taichi's ``from_numpy``."""
        io, k = self._index(f)
        m = f.n if isinstance(f, ti.MatrixField) else 1
        src = np.asarray(array)
        expected = tuple(f.shape) + ((m,) if isinstance(f, ti.MatrixField) else ())
        if src.shape != expected:
            raise ValueError(f"FieldPool.write: expected an array of shape {expected}, "
                             f"got {src.shape}")
        if io is None:
            f.from_numpy(np.array(src, dtype=_numpy_dtype(f.dtype), order="C"))
            return
        io.write(k, src.size // m, np.ascontiguousarray(src.reshape(-1, m), dtype=np.float64))

    def destroy(self):
        """Free the pool's trees; a pool of an earlier :func:`generation` only drops them."""
        for annex in self._annexes:
            annex.destroy()
        if self.generation == generation():
            for tree in self._trees:
                tree.destroy()
        released(self)
        self._trees = []
        self._shared = {}
        self._loaders = []
        self._io = None
        # Taichi lists the vector fields declared since its last kernel compile and reads
        # their shapes at the next one: a pool destroyed before any kernel ran would leave
        # freed SNodes in that list, and the next compile would crash the process
        runtime = ti.lang.impl.get_runtime()
        pending = getattr(runtime, "matrix_fields", None)
        if pending:
            mine = {id(f) for f in self.fields}
            runtime.matrix_fields = [f for f in pending if id(f) not in mine]


@ti.data_oriented
class Extent:
    """The size of the images whose planes have the shape of their size bucket: ``H`` and
    ``W`` for the host, and a field of the bucket tree that kernels read them from at run
    time (:meth:`height`, :meth:`width`), so that their code holds nothing of the size and
    compiles once per bucket (see :class:`FieldPool`).

    Kernels write the ``H x W`` region of a plane (and its margins) only: what lies beyond
    stays zero.  The per-iteration kernels loop over the whole bucket with compile-time
    bounds and skip the rest (a loop with run-time bounds made Taichi's kernels up to twice
    as slow).  :meth:`image` reads the region back and :meth:`padded` pads an
    ``(H, W, ...)`` array to the bucket for ``from_numpy``.

    A kernel whose float code must stay that of one size keeps ``H`` and ``W`` as
    compile-time constants (and compiles once per size): Taichi compiles with LLVM's
    fast-math reassociation, which orders a long sum by how its terms' addresses are
    computed, so run-time sizes, or planes of the bucket's strides, can round some sums
    differently (a few ulp).  Each kernel here was checked to give the results of kernels
    compiled for one size, bit for bit, on whole solves at several sizes.
    """

    def __init__(self, pool, height, width):
        self.H, self.W = int(height), int(width)
        self.bucket = bucket_shape(self.H, self.W)
        self.pool = pool
        self.size = pool.field(ti.i32, (2,), bucket=True)
        pool.host(self.size)
        pool.on_load(self.load)

    def load(self):
        """Write ``H`` and ``W`` into the field (the pool calls it)."""
        self.pool.write(self.size, np.array([self.H, self.W]))

    @ti.func
    def height(self):
        return self.size[0]

    @ti.func
    def width(self):
        return self.size[1]

    def image(self, f):
        """The ``H x W`` region of a bucket-shaped field as a numpy array."""
        return np.ascontiguousarray(self.pool.read(f)[:self.H, :self.W])

    def padded(self, array):
        """``array`` (``(H, W, ...)``) zero-padded to the bucket's shape."""
        array = np.asarray(array)
        out = np.zeros(self.bucket + array.shape[2:], array.dtype)
        out[:self.H, :self.W] = array
        return out
