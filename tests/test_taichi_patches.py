"""The front-end patches return Taichi's own values (lss_kernels.kernels.taichi_patches)."""
import random
import textwrap

from lss_kernels.kernels import taichi_patches


def test_fast_wrap_is_textwrap():
    """The wrapping of a line that fits the width is textwrap's own, whitespace runs at
    either end, blank and empty lines, lines at the width and over it included."""
    taichi_patches.install()
    from taichi.lang.ast import ast_transformer_utils as utils
    fast, plain = utils.TextWrapper(width=80), textwrap.TextWrapper(width=80)
    rng = random.Random(0)
    alphabet = "  ^ab(x)=,.-_:[]1"
    texts = ["", " ", "    ", "x", "  x", "x  ", "  x = 1  ", " " * 79 + "^", "^" * 80,
             "a" * 81, " " * 81, "  " + "^" * 78 + "  ", "\tx = 1", "x\ty", "é = 1  "]
    texts += ["".join(rng.choice(alphabet) for _ in range(rng.randrange(0, 90)))
              for _ in range(3000)]
    for source in (taichi_patches.__file__, textwrap.__file__):
        with open(source) as f:
            texts += f.read().splitlines()
    for _ in range(2):              # the second time, the longer texts from the memo
        for text in texts:
            assert fast.wrap(text) == plain.wrap(text), repr(text)
    assert taichi_patches.fits(fast, "  x = 1  ") and not taichi_patches.fits(fast, "x\ty")
    assert taichi_patches.plain(fast) and not taichi_patches.plain(
        utils.TextWrapper(width=80, initial_indent="> "))


def _both(stacklevel):
    """Taichi's traceback text and the patched one, captured from this same frame."""
    from taichi.lang import impl
    from taichi.lang.util import get_traceback
    lazy = impl.get_traceback(stacklevel)
    return str(lazy), get_traceback(stacklevel), lazy


def _nested(depth, stacklevel):
    return _both(stacklevel) if depth == 0 else _nested(depth - 1, stacklevel)


def test_a_fields_traceback_is_taichis_text_when_read():
    """The stack kept with a field (impl.get_traceback, patched) reads as Taichi's own
    text, at any depth and stack level, also in an f-string; a field that is never placed
    is reported with its traceback as a string, as before."""
    from taichi.lang import impl
    taichi_patches.install()
    assert getattr(impl.get_traceback, "_lss_lazy", False)
    for depth in (0, 3):
        for stacklevel in (1, 2, 4):
            got, want, lazy = _nested(depth, stacklevel)
            assert got == want and want.count("File ") > 3
            assert f"{lazy}" == want and f"x{lazy}y" == f"x{want}y"
    got, want, _ = _both(10 ** 6)               # deeper than the stack: no frames
    assert got == want == ""
    _, want, lazy = _both(1)

    class Var:                                   # a field as create_field_member leaves it
        declaration_tb, ptr = lazy, None
    text = impl.PyTaichi._get_tb(Var())          # joined into the not-placed message
    assert isinstance(text, str) and "".join([text, text]) == 2 * want
