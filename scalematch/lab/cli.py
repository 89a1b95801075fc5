"""The lab's command group, ``scalematch lab``: the benchmark, the studies, the covariance.

Each command's module is imported when the command is used, so ``scalematch lab --help`` and one
study do not load the others.
"""

from __future__ import annotations

import importlib
from typing import List, Optional

import click

#: Lab commands: name -> (module, attribute), imported on first use.
LAB_COMMANDS = {
    "bench": ("scalematch.lab.bench", "bench_command"),
    "real-pairs": ("scalematch.lab.realpairs", "real_pairs_command"),
    "ef-pairs": ("scalematch.lab.efpairs", "ef_pairs_command"),
    "3d-pairs": ("scalematch.lab.threed", "threed_pairs_command"),
    "3d-reference": ("scalematch.lab.threed", "reference_command"),
    "repeatability": ("scalematch.lab.repeatability", "repeatability_command"),
    "descriptor-study": ("scalematch.lab.descriptor_study", "descriptor_study_command"),
    "covariance": ("scalematch.lab.covariance", "covariance_command"),
    "nulls": ("scalematch.lab.nulls", "nulls_command"),
    "regress": ("scalematch.lab.regress", "regress_command"),
}


class LabGroup(click.Group):
    """A group whose commands are imported from their modules on first use."""

    def get_command(self, ctx: click.Context, name: str) -> Optional[click.Command]:
        if name not in LAB_COMMANDS:
            return None
        module, attr = LAB_COMMANDS[name]
        return getattr(importlib.import_module(module), attr)

    def list_commands(self, ctx: click.Context) -> List[str]:
        return list(LAB_COMMANDS)


@click.group("lab", cls=LabGroup,
             context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100})
def lab() -> None:
    """Research commands: the benchmark against the peers, the real pairs (ef-pairs and
    3d-pairs: the fundamental matrix on 3-D scenes; 3d-reference fits the latter's reference
    Fs), the repeatability and descriptor studies, and the estimation of the jet covariance
    Lambda.

    \b
    Examples:
      scalematch lab bench --photos 10 --methods scalematch,sift
      scalematch lab repeatability --out-dir docs/results
      scalematch lab covariance photos/*.jpg -o my_covariance.json
    """
