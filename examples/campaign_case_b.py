"""A Monte-Carlo study as a campaign: case B of the paper over noise seeds, on Dask workers.
=========================================================================================

examples/campaigns/case_b.toml describes the study (the 1-DOF oscillator under a 10 N
step, quantised + 40 dB noise, the paper and robust online methods); here it runs over 6
seeds on a local cluster of 2 worker processes, the results streamed to a Parquet file;
the summary table and the error distributions per method follow. The same spec runs on a
cluster with ``duffid campaign examples/campaigns/case_b.toml --scheduler tcp://host:8786``.

Run: python examples/campaign_case_b.py [--out out/campaign_example]
"""
from __future__ import annotations

import argparse
from pathlib import Path

from duffid.campaign import load_spec, run_campaign
from duffid.campaign.summary import summary_lines, write_plots

SPEC = Path(__file__).resolve().parent / "campaigns" / "case_b.toml"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.partition("\n")[0])
    parser.add_argument("--out", type=Path, default=Path("out/campaign_example"))
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    spec = load_spec(SPEC, seeds=6)
    output = args.out / "case_b.parquet"
    done = run_campaign(spec, output, workers=2, resume=output.exists(), progress=False)
    print(f"{done.ran} runs on {done.workers} workers in {done.seconds:.1f} s "
          f"({done.skipped} already in {output})")
    for line in summary_lines(done.table, spec):
        print(line)
    for path in write_plots(done.table, spec, args.out):
        print(f"plot: {path}")


if __name__ == "__main__":
    main()
