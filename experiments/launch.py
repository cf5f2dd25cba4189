r"""Run one experiment as several processes on this machine, joined by jax.distributed.

  python -m experiments.launch --processes=4 --gpus_per_process=1 \
      --command="python -m experiments.tables --eval=data/eval --models=out/table1"

Each process runs the same program and takes its share of the independent
jobs (``experiments.pipeline.distributed``); on a cluster, ``srun`` plays this
launcher's part. The exit status is the first failing process's (75 when one
stopped at a ``--time_limit`` given in the command: the others are interrupted,
and running the same launch again resumes).
"""

from __future__ import annotations

import dataclasses
import shlex
import sys

from experiments.pipeline import cli, deadline, distributed


@dataclasses.dataclass(frozen=True)
class Args:
  """A multi-process launch from the command line.

  Attributes:
    command: the program every process runs, as one shell-quoted string.
    processes: processes to run, e.g. one per GPU.
    gpus_per_process: GPUs each process sees (CUDA_VISIBLE_DEVICES); 0: all.
    port: the coordinator's port on localhost.
  """

  command: str = cli.required()
  processes: int = 2
  gpus_per_process: int = 0
  port: int = 12355


def main(args: Args) -> None:
  code = distributed.launch(
    shlex.split(args.command), args.processes, port=args.port,
    gpus_per_process=args.gpus_per_process,
  )  # fmt: skip
  if code == deadline.EXIT_STATUS:
    print(
      f'a process stopped at its --time_limit; resume with: {cli.resume_command()}',
      file=sys.stderr,
    )
  if code:
    sys.exit(code)


if __name__ == '__main__':
  cli.run(Args, {'default': Args()}, main)
