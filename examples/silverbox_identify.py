"""Identify the Silverbox electronic Duffing oscillator from real measurements.
============================================================================

``m y'' + d y' + k y + k2 y^2 + k3 y^3 + offset = u`` is identified on the training part
of the Silverbox multisine record with the online algebraic estimator (settings chosen
by rule from the data), refined offline by output error, and simulated on the three
standard test records. Takes about 15 s with a C compiler (the estimator runs over 390k
upsampled samples on the C core; several minutes in Python without one).

The data are read from ../shared/data/silverbox/ next to the repository or from PATH,
never copied; without them the example says so and exits.

Run: python examples/silverbox_identify.py [PATH] [--out DIR] [--no-refine]
"""
from __future__ import annotations

import argparse
from pathlib import Path

from duffid.analysis.silverbox import choose_settings, identify_silverbox, load_silverbox
from duffid.apps.plots import plot_silverbox
from duffid.data.record import RecordError


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.partition("\n")[0])
    parser.add_argument("path", nargs="?", type=Path, default=None, help="folder holding SNLS80mV.mat")
    parser.add_argument("--out", type=Path, default=Path("out"), help="folder for the plot (default out/)")
    parser.add_argument("--no-refine", action="store_true", help="algebraic estimate only")
    args = parser.parse_args()
    try:
        data = load_silverbox(args.path)
    except RecordError as exc:
        print(f"Silverbox example skipped: {exc}")
        return
    settings = choose_settings(data.training)
    print(f"training record: {data.training.n_samples} samples at {data.training.fs:.2f} Hz")
    print(f"linear ARX fit: resonance {settings.linear.natural_frequency:.2f} Hz, damping ratio "
          f"{settings.linear.damping_ratio:.4f} -> upsample x{settings.factor}, window {1e3 * settings.window:.1f} ms")
    result = identify_silverbox(data.path, refine_model=not args.no_refine)
    print(result.format())
    args.out.mkdir(parents=True, exist_ok=True)
    png = args.out / "silverbox.png"
    plot_silverbox(result, png)
    print(f"wrote {png}")


if __name__ == "__main__":
    main()
