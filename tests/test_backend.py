"""backend: the memoised source positions and source reading of Taichi's front end give
Taichi's own text."""
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


def test_source_reading_matches_taichi(ti_arch):
    from taichi.lang import kernel_impl
    read = kernel_impl.getsourcelines
    assert getattr(read, "_lss_memoised", False), "backend.init did not install the cache"
    expected = read.original(_sample)
    assert read(_sample) == expected and read(_sample) == expected   # built, then cached
    assert expected[1] == inspect.getsourcelines(_sample)[1]
    wrap = kernel_impl.textwrap
    for line in expected[0] + ["\tx = 1  # a tab", "    y = 2\n"]:
        assert wrap.fill(line, tabsize=4, width=9999) == textwrap.fill(line, tabsize=4,
                                                                       width=9999)
    assert wrap.dedent("".join(expected[0])) == textwrap.dedent("".join(expected[0]))
    assert wrap.TextWrapper is textwrap.TextWrapper     # the rest of the module, unchanged


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


def test_pool_field_in_another_memory_order_keeps_its_indexing(ti_arch):
    import numpy as np
    from lss_kernels.backend import ROWS_DISPARITIES_COLUMNS, FieldPool
    pool = FieldPool()
    vol = pool.field(ti.f32, (3, 5, 4), order=ROWS_DISPARITIES_COLUMNS)
    out = pool.field(ti.f32, (3, 5, 4))
    pool.finalize()
    try:
        values = np.arange(60, dtype=np.float32).reshape(3, 5, 4)
        vol.from_numpy(values)

        @ti.kernel
        def copy():
            for y, x, k in vol:          # iterates in vol's memory order
                out[y, x, k] = vol[y, x, k] + 1000.0 * (vol[y, x, k] == values_at(y, x, k))

        @ti.func
        def values_at(y, x, k):
            return ti.cast(y * 20 + x * 4 + k, ti.f32)

        copy()
        np.testing.assert_array_equal(vol.to_numpy(), values)
        np.testing.assert_array_equal(out.to_numpy(), values + 1000.0)
        assert pool.nbytes == 2 * 60 * 4
    finally:
        pool.destroy()
