"""backend: the memoised source positions and source reading of Taichi's front end give
Taichi's own text."""
import ast
import inspect
import os
import textwrap
from types import SimpleNamespace

import numpy as np
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
    from lss_kernels.kernels.backend import ROWS_DISPARITIES_COLUMNS, FieldPool
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


CACHE_SCRIPT = r"""
import json, sys
from pathlib import Path
from lss_kernels.kernels import backend
from lss_kernels.params import Params
from lss_kernels.scenes import make_scene
from lss_kernels.solver import Solver

cache = Path(sys.argv[1])
backend.init("cpu", threads=1, offline_cache=True)
scene = make_scene("tiny")
seen = []

def solve(d_max):
    # ten iterations: the prior, the upward pass and a re-initialisation; then the left view
    s = Solver(scene.left, scene.right, d_max, scene.init_ellipse,
               params=Params(max_iterations=10, stop_shift=0.0))
    s.run()
    s.left_view()
    s.close()
    backend.restart()                   # also writes the cache of the program it ends
    seen.append(sorted(p.name for p in cache.rglob("*") if p.is_file()))

solve(scene.d_max)
solve(scene.d_max + 4)                  # same size, another search range
solve(scene.d_max)                      # the first again, after another solver
print(json.dumps(seen))
"""


@pytest.mark.slow
def test_kernels_without_volumes_are_cached_across_search_ranges(tmp_path, ti_arch):
    """Taichi keys a kernel's offline-cache entry on the SNode trees it touches.  With the
    volumes in a tree of their own, a new search range at a known image size compiles only
    the kernels that read a volume; after ``backend.restart`` a solver finds the entries a
    fresh process made for its size and range, whatever was built before it."""
    import json
    import os
    import subprocess
    import sys
    if ti_arch != "cpu":
        pytest.skip("the offline cache is exercised on the CPU")
    cache = tmp_path / "cache"
    env = dict(os.environ, TI_OFFLINE_CACHE_FILE_PATH=str(cache))
    proc = subprocess.run([sys.executable, "-c", CACHE_SCRIPT, str(cache)], env=env,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    first, second, third = (set(s) for s in json.loads(proc.stdout.splitlines()[-1]))
    kernels = lambda names: {n for n in names if n.endswith(".tic")}
    new = kernels(second) - kernels(first)
    assert kernels(first) and new, "the second range should compile its volume kernels"
    assert len(new) <= len(kernels(first)) // 2, (len(new), len(kernels(first)))
    assert kernels(third) == kernels(second), "the first range again compiled anew"


def test_offline_cache_holds_a_gigabyte_unless_the_environment_says(ti_arch):
    """Taichi's default 100 MB evicts kernels a pass over a few image sizes needs again;
    ``TI_OFFLINE_CACHE_MAX_SIZE_OF_FILES`` still overrides the library's limit."""
    import subprocess
    import sys
    from lss_kernels.kernels import backend
    code = ("from lss_kernels.kernels import backend; import taichi as ti; "
            "backend.init('cpu'); print(ti.lang.impl.current_cfg().offline_cache_max_size_of_files)")
    env = {k: v for k, v in os.environ.items() if k != "TI_OFFLINE_CACHE_MAX_SIZE_OF_FILES"}

    def limit(**extra):
        done = subprocess.run([sys.executable, "-c", code], env=dict(env, **extra),
                              capture_output=True, text=True, check=True)
        return int(done.stdout.split()[-1])
    assert limit() == backend.OFFLINE_CACHE_BYTES == 1 << 30
    assert limit(TI_OFFLINE_CACHE_MAX_SIZE_OF_FILES="12345") == 12345


def test_the_cpu_compiles_without_taichis_cfg_and_advanced_passes(ti_arch):
    """LLVM does their work on the CPU; without them a kernel compiles in about 60 % of the
    time (``backend.init``, docs/design.md)."""
    import subprocess
    import sys
    code = ("from lss_kernels.kernels import backend; import taichi as ti; "
            "backend.init('cpu'); c = ti.lang.impl.current_cfg(); "
            "print(c.cfg_optimization, c.advanced_optimization)")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True)
    assert done.stdout.split()[-2:] == ["False", "False"]


def test_auto_runs_on_the_cpu_with_one_line_when_no_gpu_answers(monkeypatch):
    from lss_kernels.kernels import backend
    monkeypatch.setattr(backend, "probe", lambda arch: (False, "no cuda driver library"))
    said = []
    assert backend.resolve("auto", log=said.append) == "cpu"
    assert said == ["lss: no usable CUDA GPU (no cuda driver library); running on the CPU"]


def test_auto_takes_cuda_when_a_device_answers(monkeypatch):
    from lss_kernels.kernels import backend
    monkeypatch.setattr(backend, "probe", lambda arch: (arch == "cuda", "ok"))
    assert backend.resolve("auto", log=pytest.fail) == "cuda"
    assert backend.resolve("cpu") == "cpu"


def test_gpu_without_any_gpu_is_one_clear_error(monkeypatch):
    from lss_kernels.kernels import backend
    monkeypatch.setattr(backend, "probe", lambda arch: (False, f"no {arch} driver library"))
    with pytest.raises(ValueError, match=r"^arch: 'gpu' found no usable GPU backend \(cuda: "
                                         r"no cuda driver library; vulkan: .*\)$"):
        backend.resolve("gpu")


def test_probe_of_a_backend_the_machine_lacks_answers_instead_of_crashing(monkeypatch):
    """The probe asks Taichi in a subprocess, even when the driver library seems present: a
    backend that the machine lacks makes that process fail (or crash), never the caller."""
    from lss_kernels.kernels import backend
    lacks_cuda = not backend._library_present("cuda")
    monkeypatch.setattr(backend, "_probed", {})
    monkeypatch.setattr(backend, "_library_present", lambda arch: True)
    usable, reason = backend.probe("cuda", timeout=120)
    assert isinstance(usable, bool) and reason
    if lacks_cuda:
        assert not usable


REUSE_SCRIPT = """
import sys
from lss_kernels import solve
from lss_kernels.kernels import backend
from lss_kernels.params import Params
from lss_kernels.scenes import make_scene

backend.init("cpu", threads=1, offline_cache=True, reuse_kernels=sys.argv[1] == "reuse")
scene = make_scene("tiny")
for refine in sys.argv[2].split(","):
    # three iterations: the prior and validity enter at the second
    solve(scene.left, scene.right, scene.d_max, scene.init_ellipse,
          params=Params(max_iterations=3, stop_shift=0.0, refine=refine == "refine",
                        recover=False))
"""


def _entries_after(tmp_path, mode, solves):
    """The offline cache's kernels after a fresh process ran ``solves`` (``"plain"`` or
    ``"refine"`` each, comma-separated); Taichi writes the cache at exit."""
    import os
    import subprocess
    import sys
    cache = tmp_path / f"{mode}-{solves}"
    env = dict(os.environ, TI_OFFLINE_CACHE_FILE_PATH=str(cache))
    proc = subprocess.run([sys.executable, "-c", REUSE_SCRIPT, mode, solves], env=env,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return {p.name for p in cache.rglob("*.tic")}


@pytest.mark.slow
def test_a_second_solve_in_one_process_compiles_nothing(tmp_path, ti_arch):
    """``solve()`` twice in one process (a robot's loop): the second solver starts Taichi
    again first and loads every kernel the first compiled; with ``reuse_kernels=False`` its
    SNodes are numbered after the first's and every kernel compiles again."""
    if ti_arch != "cpu":
        pytest.skip("the offline cache is exercised on the CPU")
    one = _entries_after(tmp_path, "reuse", "plain")
    assert one and _entries_after(tmp_path, "reuse", "plain,plain") == one
    assert len(_entries_after(tmp_path, "no-reuse", "plain,plain") - one) >= len(one) // 2
    # the refinement's fields are in an annex of the pool: a refining solve's kernels have
    # the keys of a plain solve's but for the refinement's own (21 of 74; with them in the
    # pool's trees every key differed)
    refine = _entries_after(tmp_path, "reuse", "refine")
    assert 0 < len(refine - one) <= len(refine) // 2, (len(refine - one), len(refine))


def test_a_new_solver_starts_taichi_again_only_when_no_field_is_alive(ti_arch):
    from lss_kernels import Params, Solver
    from lss_kernels.kernels import backend
    from lss_kernels.scenes import make_scene
    scene = make_scene("tiny")
    params = Params(max_iterations=1)          # the fields of every default tiny solve
    build = lambda: Solver(scene.left, scene.right, scene.d_max, scene.init_ellipse,
                           params=params)
    a = build()
    start = backend.generation()
    a.step()
    phi = a.levelset.extent.image(a.levelset.phi)
    b = build()                                 # `a` is alive: no restart
    assert backend.generation() == start
    np.testing.assert_array_equal(a.levelset.extent.image(a.levelset.phi), phi)
    b.close()
    a.close()
    c = build()                                 # nothing alive: numbered from 0 again
    assert backend.generation() == start + 1
    stale = backend.FieldPool()
    stale.generation = start                    # a pool of the Taichi that is gone
    stale._trees = list(c.pool._trees)
    stale.destroy()                             # drops them without freeing c's trees
    c.step()
    assert np.isfinite(c.levelset.extent.image(c.levelset.phi)).all()
    c.close()
