"""Shadow-quality report: the ground-truth tool run over the test scenes and a settings sweep.

Owns ``python -m csm_engine.quality_report`` (issue 5). For each bundled scene
(``data/scenes/default.json``, ``shadow_test.json``, ``point_lights.json``) it renders the
Cycles reference once (Cycles does not depend on any CSM setting) and then, for each
point, renders CSM and compares with ``ground_truth.compare_engines``:

- a sweep of one setting at a time around the defaults: ``depth_bias``, ``slope_bias``,
  ``normal_offset``, ``pcf_radius``, ``split_lambda``, ``resolution``, ``stabilize``;
- the acne experiment: no bias and no culling, front-face culling only, constant bias
  only, slope-scaled bias only, normal offset only, the defaults.

Every setting is put back after each point. Outputs (``--out-dir``, default ``docs``):
- ``images/quality_<setting>.png``: mismatch, false shadow and missed shadow against the
  setting, one line per scene, the default marked (needs matplotlib; without it the tool
  says so and writes everything else);
- ``images/quality_worst_<setting>.png``: the heat map of the sweep's worst point;
- ``images/acne_<technique>.png``: the acne experiment's heat maps on the scene where one
  technique alone leaves the most false shadow;
- ``shadow-acne.md``: the tables between ``<!-- BEGIN GENERATED -->`` and
  ``<!-- END GENERATED -->``; the prose around them is left alone;
- ``--json FILE``: every point's numbers.

``--quick`` is a smoke run for the tests: shadow_test only, 240x135, a few points, and
(unless ``--out-dir`` is given) a folder in the temp directory, so it never overwrites
the numbers in ``docs``.
"""

import argparse
import datetime
import json
import os
import platform
import tempfile
import time

import numpy as np

from . import ground_truth

SCENES = ("shadow_test", "default", "point_lights")
DEFAULT_RESOLUTION = "1280x720"
QUICK_RESOLUTION = "240x135"

SWEEPS = (
    ("depth_bias", (0.0, 0.25, 0.5, 1.0, 2.0, 4.0, 8.0)),
    ("slope_bias", (0.0, 0.1, 0.25, 0.5, 1.0, 2.0, 4.0)),
    ("normal_offset", (0.0, 0.25, 0.5, 1.0, 2.0, 4.0)),
    ("pcf_radius", (0, 1, 2, 3)),
    ("split_lambda", (0.0, 0.25, 0.5, 0.75, 0.9, 1.0)),
    ("resolution", (512, 1024, 2048, 4096)),
    ("stabilize", (False, True)),
)
QUICK_SWEEPS = (("depth_bias", (1.0, 8.0)),)

NO_BIAS = {"depth_bias": 0.0, "slope_bias": 0.0, "normal_offset": 0.0,
           "cull_front_faces": False}
# (name, title, settings). Each technique alone at its default value.
ACNE_TECHNIQUES = (
    ("none", "no bias, no culling", dict(NO_BIAS)),
    ("front_face_culling", "front-face culling only", dict(NO_BIAS, cull_front_faces=True)),
    ("constant", "constant offset only", dict(NO_BIAS, depth_bias=None)),
    ("slope", "slope-scaled bias only", dict(NO_BIAS, slope_bias=None)),
    ("normal_offset", "normal offset only", dict(NO_BIAS, normal_offset=None)),
    ("defaults", "defaults (constant + slope + normal offset)", {}),
)
QUICK_ACNE = ("none", "defaults")

BEGIN, END = "<!-- BEGIN GENERATED -->", "<!-- END GENERATED -->"
METRICS = (("mismatch_percent", "mismatch"), ("false_shadow_percent", "false shadow"),
           ("missed_shadow_percent", "missed shadow"))


def _format_value(value):
    if isinstance(value, bool):
        return "on" if value else "off"
    return f"{value:g}"


def _describe(settings):
    return " ".join(f"{k}={_format_value(v)}" for k, v in settings.items()) or "defaults"


def plan_points(scenes, sweeps, acne_names, defaults):
    """Every point as a dict: scene, group ("sweep" / "acne"), setting or technique, value,
    settings (the full override dict)."""
    points = []
    for scene in scenes:
        for setting, values in sweeps:
            for value in values:
                points.append(dict(scene=scene, group="sweep", setting=setting,
                                   value=value, settings={setting: value}))
        for name, title, settings in ACNE_TECHNIQUES:
            if name not in acne_names:
                continue
            settings = {k: (defaults[k] if v is None else v) for k, v in settings.items()}
            points.append(dict(scene=scene, group="acne", technique=name, title=title,
                               settings=settings))
    return points


def _acne_scene(points):
    """The scene for the acne heat maps: where one technique alone leaves the most false
    shadow, so the techniques' differences show (every scene is covered in acne without
    any). With only "none" and "defaults" measured: where "none" has the most."""
    acne = [p for p in points if p["group"] == "acne"]
    if not acne:
        return None
    single = [p for p in acne if p["technique"] not in ("none", "defaults")] or acne
    return max(single, key=lambda p: p["result"]["false_shadow_percent"])["scene"]


def _label(point):
    if point["group"] == "sweep":
        return f"{point['setting']}={_format_value(point['value'])}"
    return f"acne {point['technique']} ({_describe(point['settings'])})"


# ----------------------------------------------------------------------------- plots

def _plot_sweeps(points, sweeps, defaults, scenes, images):
    """Write quality_<setting>.png per sweep and quality_acne.png; returns the paths, or
    None when matplotlib is missing."""
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return None
    written = []
    for setting, values in sweeps:
        fig, axes = plt.subplots(1, 3, figsize=(13, 3.8))
        for scene in scenes:
            rows = [p for p in points if p["scene"] == scene and p["group"] == "sweep"
                    and p["setting"] == setting]
            xs = [float(p["value"]) for p in rows]
            for ax, (key, title) in zip(axes, METRICS):
                ax.plot(xs, [p["result"][key] for p in rows], marker="o", label=scene)
        for ax, (key, title) in zip(axes, METRICS):
            ax.axvline(float(defaults[setting]), color="grey", linestyle="--",
                       label=f"default {_format_value(defaults[setting])}")
            ax.set_title(f"{title} %")
            ax.set_xlabel(setting)
            ax.set_yscale("symlog", linthresh=0.01)
            top = max((line.get_ydata().max() for line in ax.get_lines()
                       if len(line.get_ydata()) > 2 or line.get_label() in scenes),
                      default=1.0)
            ax.set_ylim(0, max(top, 0.01) * 2.0)
            ax.grid(True, alpha=0.3)
            if setting == "resolution":
                ax.set_xscale("log", base=2)
            if setting == "stabilize":
                ax.set_xticks([0, 1], ["off", "on"])
        axes[0].set_ylabel("% of compared pixels")
        axes[0].legend(fontsize=8)
        fig.tight_layout()
        path = os.path.join(images, f"quality_{setting}.png")
        fig.savefig(path, dpi=80)
        plt.close(fig)
        written.append(path)

    acne = [p for p in points if p["group"] == "acne"]
    if acne:
        names = [n for n, _, _ in ACNE_TECHNIQUES if any(p["technique"] == n for p in acne)]
        fig, axes = plt.subplots(1, 2, figsize=(13, 4))
        width = 0.8 / len(scenes)
        for i, scene in enumerate(scenes):
            by_name = {p["technique"]: p for p in acne if p["scene"] == scene}
            xs = np.arange(len(names)) + (i - (len(scenes) - 1) / 2) * width
            for ax, key in zip(axes, ("false_shadow_percent", "missed_shadow_percent")):
                ax.bar(xs, [by_name[n]["result"][key] for n in names], width, label=scene)
        for ax, title in zip(axes, ("false shadow (acne) %", "missed shadow (peter-panning) %")):
            ax.set_xticks(np.arange(len(names)), names, rotation=20, fontsize=8)
            ax.set_yscale("symlog", linthresh=0.01)
            top = max((bar.get_height() for bar in ax.patches), default=1.0)
            ax.set_ylim(0, max(top, 0.01) * 2.0)
            ax.set_title(title)
            ax.grid(True, axis="y", alpha=0.3)
        axes[0].legend(fontsize=8)
        fig.tight_layout()
        path = os.path.join(images, "quality_acne.png")
        fig.savefig(path, dpi=80)
        plt.close(fig)
        written.append(path)
    return written


# -------------------------------------------------------------------------- markdown

def _cell(result):
    return (f"{result['mismatch_percent']:.3f} / {result['false_shadow_percent']:.3f} / "
            f"{result['missed_shadow_percent']:.3f}")


def build_markdown(report, points, sweeps, scenes, defaults, worst, acne_scene, plotted):
    lines = [
        f"Generated by `{report['command']}` on {report['date']}: {report['resolution']}, "
        f"{report['points']} points ({report['renders']} distinct CSM renders), "
        f"{report['runtime_s']:.0f} s, Blender {report['blender']}, {report['machine']}.",
        "Each cell is **mismatch / false shadow / missed shadow**, in % of the compared "
        "pixels (see [ground-truth.md](ground-truth.md)).",
        "",
    ]
    acne = [p for p in points if p["group"] == "acne"]
    if acne:
        lines += ["### Acne experiment", "",
                  "| technique | settings | " + " | ".join(scenes) + " |",
                  "|---|---|" + "---|" * len(scenes)]
        for name, title, _ in ACNE_TECHNIQUES:
            rows = {p["scene"]: p for p in acne if p["technique"] == name}
            if not rows:
                continue
            first = next(iter(rows.values()))
            lines.append(f"| {title} | `{_describe(first['settings'])}` | "
                         + " | ".join(_cell(rows[s]["result"]) for s in scenes) + " |")
        lines.append("")
        if plotted:
            lines += ["![acne experiment, false and missed shadow per technique]"
                      "(images/quality_acne.png)", ""]
        if acne_scene:
            lines += [f"Heat maps on `{acne_scene}`, the scene where one technique alone "
                      "leaves the most false shadow (red = false shadow, blue = missed "
                      "shadow, light grey = both lit, dark grey = both shadowed):", ""]
            for name, title, _ in ACNE_TECHNIQUES:
                rows = [p for p in acne if p["technique"] == name and p["scene"] == acne_scene]
                if rows:
                    r = rows[0]["result"]
                    lines += [f"![{title}](images/acne_{name}.png)", "",
                              f"*{title}*: false shadow {r['false_shadow_percent']:.3f} %, "
                              f"missed shadow {r['missed_shadow_percent']:.3f} %, shadow lost "
                              f"{r['shadow_lost_percent']:.1f} %.", ""]
    lines += ["### Best value of each setting", "",
              "The swept value with the lowest mismatch on each scene (ties: the first), "
              "against the default.", "",
              "| setting | default | " + " | ".join(f"best on {s}" for s in scenes) + " |",
              "|---|---|" + "---|" * len(scenes)]
    for setting, values in sweeps:
        cells = []
        for scene in scenes:
            rows = [p for p in points if p["group"] == "sweep" and p["setting"] == setting
                    and p["scene"] == scene]
            best = min(rows, key=lambda p: round(p["result"]["mismatch_percent"], 6))
            at_default = [p for p in rows if p["value"] == defaults[setting]]
            text = (f"{_format_value(best['value'])} "
                    f"({best['result']['mismatch_percent']:.3f} %")
            if at_default:
                text += f" vs {at_default[0]['result']['mismatch_percent']:.3f} %"
            cells.append(text + ")")
        lines.append(f"| `{setting}` | {_format_value(defaults[setting])} | "
                     + " | ".join(cells) + " |")
    lines.append("")
    for setting, values in sweeps:
        lines += [f"### `{setting}` (default {_format_value(defaults[setting])})", "",
                  f"| {setting} | " + " | ".join(scenes) + " |",
                  "|---|" + "---|" * len(scenes)]
        for value in values:
            rows = {p["scene"]: p for p in points if p["group"] == "sweep"
                    and p["setting"] == setting and p["value"] == value}
            mark = " (default)" if value == defaults[setting] else ""
            lines.append(f"| {_format_value(value)}{mark} | "
                         + " | ".join(_cell(rows[s]["result"]) for s in scenes) + " |")
        lines.append("")
        if plotted:
            lines += [f"![{setting} sweep](images/quality_{setting}.png)", ""]
        if setting in worst:
            w = worst[setting]
            lines += [f"Worst point: `{w['scene']}` with `{setting}="
                      f"{_format_value(w['value'])}`, mismatch "
                      f"{w['result']['mismatch_percent']:.3f} %.", "",
                      f"![worst {setting}](images/quality_worst_{setting}.png)", ""]
    return "\n".join(lines).rstrip() + "\n"


def write_markdown_section(path, body):
    """Replace what lies between the markers in ``path``; a missing file gets a title and
    the markers, a file without markers gets them appended."""
    if os.path.isfile(path):
        with open(path, encoding="utf-8") as stream:
            text = stream.read()
    else:
        text = f"# Shadow acne\n\n{BEGIN}\n{END}\n"
    if BEGIN not in text or END not in text:
        text = text.rstrip() + f"\n\n{BEGIN}\n{END}\n"
    head, rest = text.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    with open(path, "w", encoding="utf-8") as stream:
        stream.write(head + BEGIN + "\n" + body + END + tail)


# ------------------------------------------------------------------------------ run

def _machine():
    text = f"{os.cpu_count()} cores, {platform.system()} {platform.machine()}"
    try:
        import gpu
        text += f", {gpu.platform.renderer_get()}"
    except Exception:      # no GPU context: the renderer is unknown, the rest still holds
        pass
    return text


def build_parser(prog="python -m csm_engine.quality_report"):
    parser = argparse.ArgumentParser(
        prog=prog,
        description="Run the ground-truth comparison over the bundled scenes and a sweep of "
                    "CSM settings (biases, PCF, split lambda, resolution, stabilization, the "
                    "acne techniques); write plots, heat maps, the tables in shadow-acne.md.")
    parser.add_argument("--quick", action="store_true",
                        help=f"smoke run: shadow_test only, {QUICK_RESOLUTION}, a few points, "
                             "into a temp folder unless --out-dir is given")
    parser.add_argument("--out-dir", metavar="DIR",
                        help="where shadow-acne.md and images/ go (default docs)")
    parser.add_argument("--resolution", metavar="WxH",
                        help=f"image size (default {DEFAULT_RESOLUTION}; "
                             f"{QUICK_RESOLUTION} with --quick)")
    parser.add_argument("--json", metavar="FILE", help="write every point's numbers as JSON")
    return parser


def run(argv, prog="python -m csm_engine.quality_report"):
    from .cli import CLIError, parse_resolution
    args = build_parser(prog).parse_args(argv)
    started = time.monotonic()
    width, height = parse_resolution(
        args.resolution or (QUICK_RESOLUTION if args.quick else DEFAULT_RESOLUTION))
    if args.out_dir:
        out_dir = args.out_dir
    elif args.quick:
        out_dir = os.path.join(tempfile.gettempdir(), "csm_quality_quick")
    else:
        out_dir = "docs"
    images = os.path.join(out_dir, "images")
    os.makedirs(images, exist_ok=True)
    if args.json:
        folder = os.path.dirname(os.path.abspath(args.json))
        if not os.path.isdir(folder):
            raise CLIError(f"--json: cannot write '{args.json}': folder '{folder}' "
                           "does not exist")

    import bpy
    from . import cli, paths, scene_builder, scene_format
    scenes = ("shadow_test",) if args.quick else SCENES
    sweeps = QUICK_SWEEPS if args.quick else SWEEPS
    acne_names = QUICK_ACNE if args.quick else tuple(n for n, _, _ in ACNE_TECHNIQUES)

    bpy.ops.wm.read_factory_settings(use_empty=True)
    cli.ensure_registered()
    rna = bpy.context.scene.csm.bl_rna.properties
    names = {s for s, _ in SWEEPS} | set(NO_BIAS)
    defaults = {n: rna[n].default for n in names}
    points = plan_points(scenes, sweeps, acne_names, defaults)
    scene_dir = os.path.dirname(paths.default_scene_path())

    worst, worst_classes, acne_classes = {}, {}, {}
    renders = 0
    step = 0
    for scene_name in scenes:
        bpy.ops.wm.read_factory_settings(use_empty=True)
        cli.ensure_registered()
        scene = bpy.context.scene
        if not hasattr(scene, "cycles"):
            raise CLIError("Cycles is not available in this Blender: enable the Cycles add-on", 4)
        scene_path = os.path.join(scene_dir, scene_name + ".json")
        try:
            scene_builder.import_scene_file(scene_path, scene)
        except (scene_format.SceneFormatError, scene_builder.SceneImportError) as error:
            raise CLIError(str(error), cli.EXIT_SCENE)
        t0 = time.monotonic()
        reference = ground_truth.cycles_visibility(scene, width, height)
        print(f"[quality] {scene_name}: Cycles reference at {width}x{height} in "
              f"{time.monotonic() - t0:.1f} s", flush=True)
        cache = {}
        for point in (p for p in points if p["scene"] == scene_name):
            step += 1
            csm = scene.csm
            # Only what differs from the defaults matters: equal settings share a render.
            effective = {k: v for k, v in point["settings"].items() if v != defaults[k]}
            key = tuple(sorted(effective.items()))
            if key not in cache:
                saved = {k: getattr(csm, k) for k in point["settings"]}
                try:
                    for k, v in point["settings"].items():
                        setattr(csm, k, v)
                    result, classes = ground_truth.compare_engines(
                        ground_truth.csm_visibility(scene, width, height), reference)
                finally:
                    for k, v in saved.items():
                        setattr(csm, k, v)
                renders += 1
                cache[key] = result.as_dict(), classes
            point["result"], classes = cache[key]
            r = point["result"]
            print(f"[quality {step}/{len(points)}] {scene_name} {_label(point)}: mismatch "
                  f"{r['mismatch_percent']:.3f} % false {r['false_shadow_percent']:.3f} % "
                  f"missed {r['missed_shadow_percent']:.3f} %", flush=True)
            if point["group"] == "acne":
                acne_classes[(scene_name, point["technique"])] = classes
            else:
                setting = point["setting"]
                if (setting not in worst or r["mismatch_percent"]
                        > worst[setting]["result"]["mismatch_percent"]):
                    worst[setting] = point
                    worst_classes[setting] = classes

    for setting, classes in worst_classes.items():
        ground_truth.write_png(os.path.join(images, f"quality_worst_{setting}.png"),
                               ground_truth.heatmap(classes)[::-1])
    acne_scene = _acne_scene(points)
    if acne_scene:
        for (scene_name, name), classes in acne_classes.items():
            if scene_name == acne_scene:
                ground_truth.write_png(os.path.join(images, f"acne_{name}.png"),
                                       ground_truth.heatmap(classes)[::-1])

    plotted = _plot_sweeps(points, sweeps, defaults, scenes, images)
    if plotted is None:
        print("[quality] matplotlib is not installed: plots skipped (pip install matplotlib); "
              "numbers, heat maps and the markdown tables are written", flush=True)

    command = "python -m csm_engine.quality_report" + (" " + " ".join(argv) if argv else "")
    report = dict(
        command=command, date=datetime.date.today().isoformat(),
        resolution=f"{width}x{height}", points=len(points), renders=renders,
        runtime_s=time.monotonic() - started, blender=bpy.app.version_string,
        machine=_machine(),
        scenes=list(scenes), defaults=defaults, acne_scene=acne_scene)
    markdown_path = os.path.join(out_dir, "shadow-acne.md")
    write_markdown_section(markdown_path, build_markdown(
        report, points, sweeps, scenes, defaults, worst, acne_scene, bool(plotted)))
    if args.json:
        report["points"] = [{k: v for k, v in p.items()} for p in points]
        with open(args.json, "w", encoding="utf-8") as stream:
            json.dump(report, stream, indent=2)
    print(f"[quality] {len(points)} points, {renders} CSM renders, "
          f"{time.monotonic() - started:.0f} s; tables in {os.path.abspath(markdown_path)}, "
          f"images in {os.path.abspath(images)}" + (f", numbers in {args.json}" if args.json
                                                    else ""), flush=True)
    return 0


def main(argv=None, prog="python -m csm_engine.quality_report"):
    from .cli import run_reporting_errors
    return run_reporting_errors(run, argv, prog, "quality report")


if __name__ == "__main__":
    from .cli import exit_process
    exit_process(main())
