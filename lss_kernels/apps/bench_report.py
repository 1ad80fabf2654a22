"""The outputs of ``lss bench``: ``scaling.csv``, ``speedup.csv``, ``scaling.png``,
``results.json`` and ``results.md`` (a markdown report), and the one-object summary of
``--json``."""
import csv
import json
import os

import numpy as np

from ..model import STAGES

__all__ = ["plot", "report", "size_series", "summary", "write_outputs"]


def write_outputs(result, out):
    """``scaling.csv``, ``speedup.csv``, ``scaling.png``, ``results.json``, ``results.md``."""
    os.makedirs(out, exist_ok=True)
    rows = result["rows"]
    if rows:
        with open(os.path.join(out, "scaling.csv"), "w", newline="") as f:
            # per-block lists stay in results.json
            wr = csv.DictWriter(f, fieldnames=[k for k, v in rows[0].items()
                                               if not isinstance(v, list)],
                                extrasaction="ignore")
            wr.writeheader()
            wr.writerows(rows)
    cmp_ = result.get("compare")
    if cmp_:
        with open(os.path.join(out, "speedup.csv"), "w", newline="") as f:
            wr = csv.writer(f)
            wr.writerow(["stage", "taichi_s", "numpy_s", "speedup"])
            for k in STAGES:
                wr.writerow([k, f"{cmp_['taichi'][k]:.6g}", f"{cmp_['numpy'][k]:.6g}",
                             f"{cmp_['speedup'][k]:.4g}"])
            wr.writerow(["iteration", f"{cmp_['taichi_iteration']:.6g}",
                         f"{cmp_['numpy_iteration']:.6g}", f"{cmp_['speedup_iteration']:.4g}"])
    if len(rows) >= 2:
        plot(result, os.path.join(out, "scaling.png"))
    with open(os.path.join(out, "results.json"), "w") as f:
        json.dump(result, f, indent=1, default=float)
    with open(os.path.join(out, "results.md"), "w") as f:
        f.write(report(result))


def size_series(rows):
    """The rows of the size sweep (first thread setting, one d_max), by pixels."""
    t0 = rows[0]["threads"]
    first = [r for r in rows if r["threads"] == t0]
    sized = [r for r in first if "size" in r["sweep"].split("+") or "compare" in r["sweep"]]
    sized = [r for r in sized if r["d_max"] == sized[0]["d_max"]] if sized else []
    return first, sorted(sized, key=lambda r: r["work"])


def plot(result, path):
    """Log-log seconds per stage vs pixels x disparities (first thread setting): lines for the
    size sweep, crosses for the other configurations (the disparity sweep), with the fitted
    exponents in the legend (matplotlib Agg, no pyplot)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    first, sized = size_series(result["rows"])
    others = [r for r in first if r not in sized]
    fig = Figure(figsize=(7.5, 5.0), dpi=90)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    for k in STAGES + ("iteration",):
        key = k if k == "iteration" else f"stage_{k}"
        e = result["exponents"].get(k, float("nan"))
        style = dict(marker="*", color="k", lw=2.0) if k == "iteration" else dict(marker="o",
                                                                                lw=1.0)
        line, = ax.loglog([r["work"] for r in sized],
                          [max(r[key], 1e-7) for r in sized], ms=3,
                          label=f"{k} (slope {e:.2f})", **style)
        if others:
            ax.loglog([r["work"] for r in others], [max(r[key], 1e-7) for r in others], "x",
                      color=line.get_color(), ms=5)
    if sized:
        w0, s0 = sized[0]["work"], sized[0]["iteration"]
        ws = np.array([r["work"] for r in sized], np.float64)
        ax.loglog(ws, s0 * ws / w0, "k:", lw=0.8, label="slope 1")
    ax.set_xlabel("pixels x cyclopean disparities (c_max = d_max / 2); "
                  "lines: size sweep, x: disparity sweep")
    ax.set_ylabel("seconds per iteration")
    ax.set_title(f"lss solver stages ({result['arch']}, threads={first[0]['threads']}); "
                 "slopes: all points")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    fig.savefig(path)


def report(result):
    """Markdown summary of a benchmark result."""
    lines = ["# lss bench results", ""]
    lines.append(f"arch: {result['arch']}, cpu_count: {result['cpu_count']}, quick: "
                 f"{result['quick']}, one process per configuration: {result['isolated']}, "
                 f"offline cache: {result['offline_cache']}; memory bandwidth "
                 f"({result.get('bandwidth_source', 'numpy copy')}, read + write): "
                 f"{result['bandwidth_gbs']:.1f} GB/s; peak RSS "
                 f"{result['maxrss_bytes'] / 2 ** 20:.0f} MiB; run time "
                 f"{result.get('seconds', float('nan')):.0f} s.")
    lines += ["", "## Per configuration (ms per iteration; setup and compile in s)", "",
              "| sweep | W x H | d_max | threads | setup | compile | iteration | "
              + " | ".join(STAGES) + " | fields MiB | model MiB | ratio | ratio (d_max) | "
              "peak RSS MiB | stream ms | bw fraction |",
              "|" + "---|" * (14 + len(STAGES))]
    for r in result["rows"]:
        lines.append(
            f"| {r['sweep']} | {r['width']}x{r['height']} | {r['d_max']} | {r['threads']} | "
            f"{r['setup']:.2f} | {r['compile']:.2f} | {1e3 * r['iteration']:.2f} | "
            + " | ".join(f"{1e3 * r['stage_' + k]:.2f}" for k in STAGES)
            + f" | {r['memory_bytes'] / 2 ** 20:.1f} | {r['memory_model_bytes'] / 2 ** 20:.1f}"
            f" | {r['memory_ratio']:.2f} | {r['memory_ratio_dmax']:.2f}"
            f" | {r['maxrss_bytes'] / 2 ** 20:.0f} | "
            f"{1e3 * r['stream_seconds']:.2f} | {r['bandwidth_fraction']:.3f} |")
    lines += ["", "model = 4 B x pixels x c_max x (levels + 2) (ratio = fields / model); "
              "ratio (d_max): the same with the d_max disparities asked for in place of the "
              "c_max = ceil(d_max / 2) cyclopean candidates the volumes hold; stream = time to "
              "read the level cost volumes once at the measured bandwidth; bw fraction = "
              "stream / iteration.",
              "", "## Fitted exponents", "",
              "| stage | vs pixels x disparities (all) | vs pixels (size sweep) |",
              "|---|---|---|"]
    for k, e in result["exponents"].items():
        lines.append(f"| {k} | {e:.2f} | {result['exponents_pixels'].get(k, float('nan')):.2f} |")
    cmp_ = result.get("compare")
    if cmp_:
        lines += ["", f"## Taichi vs numpy at {cmp_['width']}x{cmp_['height']}, d_max "
                      f"{cmp_['d_max']} (same process, same iteration indices: Taichi "
                      f"{cmp_['iterations']}, numpy {cmp_['numpy_iterations']} per block; the "
                      f"fastest of {cmp_['repeats']} interleaved blocks)", "",
                  "| stage | Taichi ms | numpy ms | speedup |", "|---|---|---|---|"]
        for k in STAGES:
            lines.append(f"| {k} | {1e3 * cmp_['taichi'][k]:.2f} | {1e3 * cmp_['numpy'][k]:.1f}"
                         f" | {cmp_['speedup'][k]:.1f} |")
        lines.append(f"| **iteration** | {1e3 * cmp_['taichi_iteration']:.2f} | "
                     f"{1e3 * cmp_['numpy_iteration']:.1f} | {cmp_['speedup_iteration']:.1f} |")
        lines += ["", f"Streaming the level cost volumes once ({cmp_['level_bytes'] / 2 ** 20:.1f}"
                      f" MiB) at the measured bandwidth takes {1e3 * cmp_['stream_seconds']:.2f} "
                      f"ms; one Taichi iteration ({1e3 * cmp_['taichi_iteration_wall']:.2f} ms "
                      f"wall) is {cmp_['bandwidth_fraction']:.3f} of that bound "
                      f"(1.0 = as fast as one pass over the volumes)."]
    return "\n".join(lines) + "\n"


def summary(result):
    """The ``--json`` object: per-stage seconds of both implementations and their speedup,
    plus exponents, bandwidth, memory and every configuration."""
    keys = ("sweep", "width", "height", "d_max", "threads", "setup", "compile", "iteration",
            "memory_bytes", "memory_model_bytes", "memory_ratio", "memory_ratio_dmax",
            "maxrss_bytes", "bandwidth_fraction", "block_iterations")
    out = dict(arch=result["arch"], quick=result["quick"], bandwidth_gbs=result["bandwidth_gbs"],
               exponents=result["exponents"], exponents_pixels=result["exponents_pixels"],
               maxrss_bytes=result["maxrss_bytes"], seconds=result.get("seconds"),
               configs=[dict({k: r[k] for k in keys},
                             stages={s: r[f"stage_{s}"] for s in STAGES})
                        for r in result["rows"]])
    cmp_ = result.get("compare")
    if cmp_:
        out.update(taichi=cmp_["taichi"], numpy=cmp_["numpy"], speedup=cmp_["speedup"],
                   taichi_iteration=cmp_["taichi_iteration"],
                   numpy_iteration=cmp_["numpy_iteration"],
                   speedup_iteration=cmp_["speedup_iteration"],
                   compare_size=[cmp_["width"], cmp_["height"], cmp_["d_max"]],
                   bandwidth_fraction=cmp_["bandwidth_fraction"],
                   repeats=cmp_["repeats"], block_taichi=cmp_["block_iterations"],
                   block_numpy=cmp_["block_numpy"])
    return out
