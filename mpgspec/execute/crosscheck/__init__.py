"""Cross-check in an independent simulator: the sequence's runs replayed in MuJoCo with the same
compiled control laws, their safety functions evaluated along MuJoCo's trajectory and compared with
mpgspec's verdicts and rollouts (the `xcheck` extra installs MuJoCo)."""
from .compare import CrossCheckResult, crosscheck_runs, runs_stage, variants_stage
from .settings import CrossCheckSettings

__all__ = ["CrossCheckResult", "CrossCheckSettings", "crosscheck_runs", "runs_stage", "variants_stage"]
