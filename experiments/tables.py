"""The paper's Tables 2 (fabrics) and 3 (garments): every evaluation recording estimated.

  python -m experiments.tables --eval=data/eval --models=out/table1 --workdir=out/tables
  python -m experiments.tables --from_json=a/tables.json,b/tables.json --workdir=out/all

What the tables hold: ``experiments.studies.tables``.
"""

from __future__ import annotations

import dataclasses
import os

from absl import logging

from experiments.pipeline import cli
from experiments.pipeline import objective as objective_lib
from experiments.studies import tables as tables_lib


@dataclasses.dataclass(frozen=True)
class Args:
  """Tables 2 and 3 from the command line.

  Attributes:
    eval: the evaluation set (make_eval_set --out).
    models: the trained networks (table1 --workdir); several folders,
      comma-separated: each network an ensemble of theirs.
    workdir: estimates, tables and figures go here.
    from_json: instead of estimating, re-tabulate these tables.json files
      (runs of different methods on one evaluation set merge).
    tables: the experiment.
  """

  eval: str = 'data/eval'
  models: str = 'out/table1'
  workdir: str = 'out/tables'
  from_json: tuple[str, ...] = ()
  tables: tables_lib.Config = tables_lib.Config()


PRESETS = {
  k: Args(tables=tables_lib.Config(estimate=tables_lib.for_networks(v)))
  for k, v in objective_lib.PRESETS.items()
}


def main(args: Args) -> None:
  logging.set_verbosity(logging.WARNING)
  if args.from_json:
    os.makedirs(args.workdir, exist_ok=True)
    tables_lib.write_report(
      tables_lib.from_json(args.from_json), args.tables, args.workdir
    )
  else:
    tables_lib.run(args.tables, args.eval, args.models, args.workdir)


if __name__ == '__main__':
  cli.run(Args, PRESETS, main)
