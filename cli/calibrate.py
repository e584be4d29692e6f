"""``navtwin calibrate``: 001's least-squares range calibration (host.calibration), on the
emulator's calibration walk in memory or on a recording, and the calibration file it writes."""
from __future__ import annotations

from .emulate import SEED_HELP, seed
from .main import UsageError, number
from .sweep import seed_range

#: 001 sect. 3.3 and 5.1: the figures the command prints beside its own
PAPER = {"range": (0.66, 0.18), "wsn_max": (1.26, 0.55), "wsn_variance": (0.2618, 0.0261)}


def register(sub) -> None:
    p = sub.add_parser(
        "calibrate", help="fit the range scale factor, anchor biases and range sd (001 LSR)",
        description="001 sect. 3.3: the tag rests at surveyed points (the step table) while the "
        "anchors range it; least squares gives the scale factor f and each anchor's bias c_i "
        "(eqs. 13-16), a polynomial the range sd as a function of distance. Prints the mean "
        "range error and the WSN-only (TOA) position error at the points before and after, "
        "beside 001's figures, and writes the calibration file that 'navtwin host "
        "--calibration FILE' (or a host config's [calibration] file) loads.")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("recording", nargs="?", metavar="REC_DIR",
                     help="a recording with the gateway's port (emulator's or host's)")
    src.add_argument("--scenario", metavar="NAME|FILE",
                     help="run this calibration scenario in memory (e.g. calibration)")
    which = p.add_mutually_exclusive_group()
    which.add_argument("--seed", type=seed, help=SEED_HELP + " (with --scenario)")
    which.add_argument("--seeds", type=seed_range, metavar="A..B",
                       help="with --scenario: run the walk once per seed (both ends included) "
                            "and print each figure's mean over the seeds with its 95 %% "
                            "Student-t interval and the paired after - before; writes no "
                            "calibration file")
    p.add_argument("--steps", default="corridor", metavar="NAME|FILE",
                   help="the step table: surveyed points and when the tag rested at each "
                        "(default: corridor, host/calibrations/corridor-steps.toml)")
    p.add_argument("--config", default="corridor", metavar="NAME|FILE",
                   help="host config with the anchor survey (default: corridor)")
    p.add_argument("--sigma-degree", type=number(0, 5, integer=True), default=2, metavar="N",
                   help="degree of the range sd polynomial, 0 to 5 (default 2; 001 uses 5)")
    p.add_argument("--out", metavar="FILE",
                   help="the calibration file to write (default calibration.toml)")
    p.add_argument("--evaluate", metavar="SCENARIO",
                   help="also run SCENARIO (e.g. corridor) in memory and print its wsn track's "
                        "error against the emulator's truth, uncorrected and calibrated")
    p.set_defaults(func=run)


def run(args) -> int:
    from navtwin.emulator.scenario import ScenarioError
    from navtwin.host import calibration as cal
    from navtwin.host import config as host_config
    from navtwin.lab import calibration as lab
    from navtwin.protocols.recording import RecordingError

    if args.seeds is not None:
        if not args.scenario:
            raise UsageError("--seeds runs a calibration scenario; give --scenario NAME (a "
                             "recording is one seed: omit --seeds)")
        if args.out:
            raise UsageError("--out writes one seed's calibration; with --seeds give none "
                             "(the table only), or use --seed N --out FILE")
    try:
        config = host_config.load(args.config)
        steps = cal.load_steps(args.steps)
        if args.seeds is not None:
            return _over_seeds(args, steps, config)
        data = lab.gateway_bytes(args.scenario, args.seed) if args.scenario else \
            lab.recorded_bytes(args.recording)
        result = lab.calibrate(data, steps, config, args.sigma_degree)
    except (host_config.ConfigError, cal.CalibrationError, ScenarioError, RecordingError) as e:
        raise UsageError(str(e)) from None
    source = f"scenario {args.scenario}" + (f" seed {args.seed}" if args.seed is not None else "") \
        if args.scenario else f"recording {args.recording}"
    c = result.calibration
    print(f"{len(steps.steps)} steps, {len(c.bias)} anchors, {result.exchanges} exchanges ({source})")
    print(f"f = {c.scale:.4f} +- {c.scale_ci95:.4f} (95 %)")
    for a in sorted(c.bias):
        print(f"c_{a} = {c.bias[a]:+.3f} +- {c.bias_ci95[a]:.3f} m")
    terms = " + ".join(f"{v:.4g} d^{k}" for k, v in enumerate(c.sigma_coefficients))
    print(f"sigma(d) = {terms} m, d in [{c.sigma_span_m[0]:.2f}, {c.sigma_span_m[1]:.2f}] m")
    rows = [("mean range error (m)", result.range_error_m, PAPER["range"], ".3f"),
            ("WSN-only max error (m)", result.wsn_max_m, PAPER["wsn_max"], ".3f"),
            ("WSN-only variance (m^2)", result.wsn_variance_m2, PAPER["wsn_variance"], ".4f")]
    if args.evaluate:
        try:
            runs = [lab.wsn_errors(args.evaluate, args.seed, config, k) for k in (None, c)]
        except ScenarioError as e:
            raise UsageError(str(e)) from None
        rows += [(f"{args.evaluate} wsn max (m)", tuple(r["max"] for r in runs), PAPER["wsn_max"], ".3f"),
                 (f"{args.evaluate} wsn variance (m^2)", tuple(r["variance"] for r in runs),
                  PAPER["wsn_variance"], ".4f"),
                 (f"{args.evaluate} wsn mean (m)", tuple(r["mean"] for r in runs), None, ".3f")]
    print(f"{'':<30}{'before':>10}{'after':>10}   paper 001")
    for name, (b, a), paper, fmt in rows:
        ref = f"{paper[0]:g} -> {paper[1]:g}" if paper else ""
        print(f"{name:<30}{_cell(b, fmt)}{_cell(a, fmt)}   {ref}")
    header = (f"navtwin calibrate: 001's LSR of f and c_i, range sd of degree {args.sigma_degree}\n"
              f"from {source}, steps {args.steps}, config {args.config}")
    out = args.out or "calibration.toml"
    try:
        with open(out, "w", encoding="utf-8") as f:
            f.write(c.to_toml(header))
    except OSError as e:
        raise UsageError(f"--out {out}: {e.strerror}; choose a writable path") from None
    print(f"wrote {out}")
    return 0


def _over_seeds(args, steps, config) -> int:
    """The table of --seeds: each figure's mean over the seeds, ± its 95 % t half-width,
    before and after, and the paired per-seed after - before."""
    from navtwin.lab import calibration as lab

    seeds = list(args.seeds)
    per = [lab.seed_figures(args.scenario, s, steps, config, args.sigma_degree, args.evaluate)
           for s in seeds]
    ev = args.evaluate
    rows = [("scale", "scale factor f", None, ".4f"),
            ("range", "mean range error (m)", PAPER["range"], ".3f"),
            ("wsn_max", "WSN-only max error at the points, in-sample (m)", None, ".3f"),
            ("wsn_variance", "WSN-only variance at the points, in-sample (m^2)", None, ".4f")]
    if ev:  # 001's WSN figures are of the moving vehicle (sect. 5.2): beside the moving run's
        rows += [("eval_max", f"{ev} wsn max error, moving (m)", PAPER["wsn_max"], ".3f"),
                 ("eval_variance", f"{ev} wsn error variance, moving (m^2)", PAPER["wsn_variance"],
                  ".4f"),
                 ("eval_mean", f"{ev} wsn mean error, moving (m)", None, ".3f")]
    then = f", then {ev} with each seed's fit" if ev else ""
    print(f"{len(seeds)} seeds {seeds[0]}..{seeds[-1]} of scenario {args.scenario}, steps "
          f"{args.steps}, config {args.config}{then}; mean over seeds ± 95 % t half-width")
    print(f"{'':<50}{'before':>18}{'after':>18}{'after - before':>20}   paper 001")
    for key, name, paper, fmt in rows:
        before = [f[key][0] for f in per]
        after = [f[key][1] for f in per]
        cells = [_ci(before, fmt, 18), _ci(after, fmt, 18),
                 _ci([a - b for a, b in zip(after, before)], fmt, 20)]
        ref = f"{paper[0]:g} -> {paper[1]:g}" if paper else ""
        print(f"{name:<50}{''.join(cells)}   {ref}".rstrip())
    return 0


def _ci(values, fmt: str, width: int) -> str:
    """The mean of *values* ± its 95 % t half-width, right-aligned; blank where NaN."""
    from navtwin.lab.evaluate import mean_ci

    m, h = mean_ci(values)
    text = "" if m != m else f"{m:{fmt}}" + ("" if h != h else f" ± {h:{fmt}}")
    return f"{text:>{width}}"


def _cell(value: float, fmt: str, width: int = 10) -> str:
    """*value* right-aligned in *width* with a space before it, in *fmt*, or in 4 significant
    digits when *fmt* would not fit: columns never run together."""
    text = f"{value:{fmt}}"
    if len(text) >= width:
        text = f"{value:.4g}"
    return f"{text:>{width}}"
