"""``python -m nerif [overrides]``: one reconstruction, or a multirun with ``-m``."""
import logging
import os
import signal
import sys
from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig

from nerif.app import run
from nerif.configs import config_dir
from nerif.io.export import write_json
from nerif.io.summary import FAILED
from nerif.solvers import DivergenceError, Interrupted


def parallel_jobs() -> int:
    """Jobs running at once on this machine: ``hydra.launcher.n_jobs`` under the joblib launcher (-1: one per
    core, -2: all but one, as joblib counts), else 1 (one job at a time, or one per Slurm allocation)."""
    launcher = HydraConfig.get().launcher
    n = launcher.get("n_jobs") if "joblib" in str(launcher.get("_target_", "")) else None
    if n is None:
        return 1
    return max(1, n if n > 0 else (os.cpu_count() or 1) + 1 + n)


def check_overrides(cfg: DictConfig, overrides) -> None:
    """One sentence for a command-line setting the run ignores: the synthetic rig's (``rig.*``) with recorded
    data, whose cameras come from the data's own files."""
    if cfg.data.name == "synthetic":
        return
    ignored = [o for o in overrides if o.lstrip("+~").startswith("rig.")]
    if ignored:
        binning = " (the binning of recorded data is data.binning)" if any("binning" in o for o in ignored) else ""
        raise ValueError(f"{', '.join(ignored)}: rig.* describes the synthetic rig; data={cfg.data.name} takes its "
                         f"cameras from its own files{binning}")


@hydra.main(version_base=None, config_path=str(config_dir()), config_name="config")
def main(cfg: DictConfig) -> float:
    try:
        check_overrides(cfg, HydraConfig.get().overrides.task)
        metrics = run(cfg, HydraConfig.get().runtime.output_dir, parallel_jobs())
    except (ValueError, FileNotFoundError, DivergenceError) as e:  # bad input or a diverged run: one sentence
        message = str(e.args[0] if len(e.args) == 1 else e)  # an OSError's own: "[Errno 2] ...: 'path'"
        logging.getLogger("nerif").error("%s", message)
        if HydraConfig.get().mode.name == "MULTIRUN":  # the sweep goes on; its summary lists the job as failed
            write_json({"error": message}, Path(HydraConfig.get().runtime.output_dir) / FAILED)
            return float("nan")
        sys.exit(2)
    except Interrupted as e:  # the loop saved a checkpoint and said so in one line
        number = getattr(signal, e.signal_name)
        launcher_handler = signal.getsignal(number)
        if e.signal_name == "SIGUSR2" and callable(launcher_handler):  # submitit's: it requeues the job, which
            launcher_handler(number, None)                            # resumes from this checkpoint
        sys.exit(128 + int(number))
    except KeyboardInterrupt:  # Ctrl-C before training (the flow, the rendering): nothing was made to keep
        logging.getLogger("nerif").error("interrupted before training began: nothing to save")
        sys.exit(130)
    return metrics.get("temperature_rmse_K", metrics["deflection_rmse"])


if __name__ == "__main__":
    main()
