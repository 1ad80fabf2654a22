"""Patches to Taichi's front end that make building a kernel cheaper, and nothing else.

Taichi (1.7) re-does two pure computations for every AST node and every inlined ``ti.func``
it visits; a 760x340 solver visits ~79,000 nodes at ~6,000 distinct positions and inlines
~1,000 function bodies.  :func:`install` keeps the first answer of each, and builds the
answers it must build faster:

* :func:`_memoise_source_positions`: the "File ..., line ..." text with the offending line and
  a caret line that Taichi builds for every node before it knows whether an error needs it
  (~2.5 s of a new solver's set-up with a warm kernel cache);
* :func:`_fast_source_lines`: the ``textwrap`` wrapping of those two lines, which for a line
  that fits in the width only drops trailing spaces, and is the same for every node of a
  longer line (1.2 s of a paper15 solve's set-up on a busy 2-core CPU, ~27,000 wraps);
* :func:`_lazy_field_tracebacks`: the text of the Python stack that Taichi keeps with every
  field it creates, for an error message about a field that is never placed: it is built
  when such a message reads it, not for each of the ~900 fields of a paper15 solve (about
  0.3 s of every solve process);
* :func:`_memoise_source_reading`: the source of a kernel or ``ti.func`` that Taichi reads with
  ``inspect`` and re-wraps with ``textwrap`` at every instance and call site (0.54 s of the
  front end's 1.6 s).

All return Taichi's own values, so compiled kernels, their debug information and the keys of
the offline cache are unchanged, and so are results.  They touch private names of Taichi
(``ASTTransformerContext.get_pos_info``, ``ast_transformer_utils.TextWrapper``,
``kernel_impl.getsourcelines`` and ``kernel_impl.textwrap``) and skip themselves when a
Taichi version lacks them.  Set the
environment variable ``LSS_TAICHI_PATCHES=0`` before the first :func:`lss_kernels.kernels.
backend.init` to leave Taichi untouched.
"""
import functools
import linecache
import os
import sys
import traceback
import types

from taichi.lang import kernel_impl as _kernel_impl
from taichi.lang import impl as _impl
from taichi.lang.ast import ast_transformer_utils as _ast_utils

__all__ = ["enabled", "install"]

#: The environment variable that turns the patches off ("0").
SWITCH = "LSS_TAICHI_PATCHES"


def enabled() -> bool:
    """Whether :func:`install` patches Taichi (``LSS_TAICHI_PATCHES`` is not "0")."""
    return os.environ.get(SWITCH, "1") != "0"


def install() -> bool:
    """Install both patches once per process, unless switched off; returns whether they are
    installed."""
    if not enabled():
        return False
    _memoise_source_positions()
    _fast_source_lines()
    _memoise_source_reading()
    _lazy_field_tracebacks()
    return True


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


def plain(wrapper) -> bool:
    """Whether ``wrapper`` (a ``TextWrapper``) has the default settings but the width."""
    return (wrapper.drop_whitespace and not wrapper.initial_indent
            and not wrapper.subsequent_indent and wrapper.max_lines is None
            and wrapper.expand_tabs and wrapper.tabsize == 8 and wrapper.replace_whitespace
            and not wrapper.fix_sentence_endings and wrapper.break_long_words
            and wrapper.break_on_hyphens and wrapper.placeholder == " [...]")


def fits(wrapper, text: str) -> bool:
    """Whether ``wrapper.wrap(text)`` is ``text`` less its trailing spaces (nothing for a
    blank text), for a :func:`plain` wrapper: a text of printable ASCII (no tab, no
    newline) that fits in the width.  ``textwrap`` then never breaks the line; it drops the
    trailing run of spaces, and keeps the leading one when something follows it."""
    return len(text) <= wrapper.width and text.isascii() and text.isprintable()


def _fast_source_lines():
    """Wrap the source line and the caret line of :func:`_memoise_source_positions`'s text
    without ``textwrap``'s chunking when they fit in its width (:func:`fits`), and each
    longer text once per process: the same lists.  Taichi builds the text once per AST node
    position of every kernel (~27,000 wraps in a 760x340 solve; 6,000 of lines over the
    width, several nodes to a line).  Skipped if this Taichi does not wrap with
    ``ast_transformer_utils.TextWrapper``."""
    base = getattr(_ast_utils, "TextWrapper", None)
    if base is None or getattr(base, "_lss_fast", False):
        return
    wrapped = {}

    class TextWrapper(base):
        _lss_fast = True

        def wrap(self, text):
            if not plain(self):
                return super().wrap(text)
            if fits(self, text):
                line = text.rstrip(" ")
                return [line] if line else []
            key = (self.width, text)
            lines = wrapped.get(key)
            if lines is None:
                lines = wrapped[key] = super().wrap(text)
            return list(lines)

    TextWrapper.original = base
    _ast_utils.TextWrapper = TextWrapper


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


class _Traceback:
    """The text of ``taichi.lang.util.get_traceback`` for a stack captured without reading
    its source lines; the text is built, the same, when first read (``str``, ``format``)."""

    __slots__ = ("_stack", "_text")

    def __init__(self, stack):
        self._stack = stack
        self._text = None

    def __str__(self):
        if self._text is None:
            # as traceback.extract_stack: the files' caches checked, then the lines read
            for filename in {filename for filename, _, _ in self._stack}:
                linecache.checkcache(filename)
            summary = traceback.StackSummary.from_list(
                [traceback.FrameSummary(filename, lineno, name, lookup_line=False)
                 for filename, lineno, name in self._stack])
            self._text = "".join(traceback.format_list(summary))
        return self._text

    def __format__(self, spec):
        return format(str(self), spec)

    def __repr__(self):
        return repr(str(self))


def _lazy_field_tracebacks():
    """Capture the stack that Taichi's ``impl`` keeps with each field (and each fields
    builder) as file names, line numbers and function names, and build its text only when an
    error message reads it (:class:`_Traceback`).  Taichi formats the whole Python stack
    (file names, source lines) for every field it creates, before it knows whether a field
    will be left unplaced: ~900 times in a paper15 solve.  The text, when read, is Taichi's
    own; the tracebacks that Taichi passes to its C++ core (``DebugInfo`` of SNodes and
    ndarrays, read with their own ``get_traceback``) are untouched.  Skipped if this
    Taichi's ``impl`` has no ``get_traceback`` or no ``PyTaichi._get_tb``, and for a stack
    that ``sys.tracebacklimit`` would cut (Taichi's own function then runs)."""
    read = getattr(_impl, "get_traceback", None)
    runtime = getattr(_impl, "PyTaichi", None)
    if read is None or getattr(read, "_lss_lazy", False) or \
            not hasattr(runtime, "_get_tb"):
        return

    def get_traceback(stacklevel=1):
        if getattr(sys, "tracebacklimit", None) is not None:
            return read(stacklevel + 1)
        try:
            frame = sys._getframe(1 + stacklevel)
        except ValueError:                  # a stack shorter than stacklevel: no frames
            return ""
        stack = []
        while frame is not None:            # as traceback.walk_stack
            code = frame.f_code
            linecache.lazycache(code.co_filename, frame.f_globals)
            stack.append((code.co_filename, frame.f_lineno, code.co_name))
            frame = frame.f_back
        stack.reverse()
        return _Traceback(stack)

    get_tb = runtime._get_tb

    def _get_tb(var):                       # joined with "".join in an error message
        return str(get_tb(var))

    get_traceback._lss_lazy = True
    get_traceback.original = read
    _impl.get_traceback = get_traceback
    runtime._get_tb = staticmethod(_get_tb)
