"""backend: the memoised source positions of Taichi's front end give Taichi's own text."""
import ast
import inspect
import textwrap
from types import SimpleNamespace

import pytest
import taichi as ti
from taichi.lang.ast.ast_transformer_utils import ASTTransformerContext


def _sample(a, b):
    total = 0.0
    for k in range(3):
        if a > b:
            total += a * k
        else:
            total -= (b
                      + k)
    return total


def test_source_positions_match_taichi_for_every_node(ti_arch):
    memoised = ASTTransformerContext.get_pos_info
    assert getattr(memoised, "_lss_memoised", False), "backend.init did not install the cache"
    lines, start = inspect.getsourcelines(_sample)
    src = [line.rstrip("\n") for line in lines]
    ctx = SimpleNamespace(file=__file__, func=SimpleNamespace(func=_sample),
                          lineno_offset=start - 1, indent=0, src=src)
    tree = ast.parse(textwrap.dedent("".join(lines)))
    nodes = [n for n in ast.walk(tree) if isinstance(n, (ast.stmt, ast.expr))]
    assert len(nodes) > 20
    for node in nodes:
        expected = memoised.original(ctx, node)
        assert memoised(ctx, node) == expected      # first call: built
        assert memoised(ctx, node) == expected      # second call: from the cache
    # a multi-line expression keeps its caret lines; line numbers are the file's
    multi = next(n for n in nodes if isinstance(n, ast.BinOp) and n.end_lineno > n.lineno)
    text = memoised(ctx, multi)
    assert f"line {multi.lineno + start - 1}" in text and text.count("^") >= 2


@ti.func
def _broken(v):
    return v + undefined_name  # noqa: F821  (the error under test)


def test_compile_errors_still_point_at_the_line(ti_arch):
    line = inspect.getsourcelines(_broken)[1] + 2
    for _ in range(2):          # the second kernel's error comes from the cache
        @ti.kernel
        def k() -> ti.f32:
            return _broken(1.0)
        with pytest.raises(ti.TaichiCompilationError) as err:
            k()
        message = str(err.value)
        assert f'line {line}, in _broken' in message and "undefined_name" in message
