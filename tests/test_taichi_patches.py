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
