"""``python -m nerif [overrides]``: one reconstruction, or a multirun with ``-m``."""
import logging
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


@hydra.main(version_base=None, config_path=str(config_dir()), config_name="config")
def main(cfg: DictConfig) -> float:
    try:
        metrics = run(cfg, HydraConfig.get().runtime.output_dir)
    except (ValueError, FileNotFoundError, DivergenceError) as e:  # bad input or a diverged run: one sentence
        message = str(e.args[0] if e.args else e)
        logging.getLogger("nerif").error("%s", message)
        if HydraConfig.get().mode.name == "MULTIRUN":  # the sweep goes on; its summary lists the job as failed
            write_json({"error": message}, Path(HydraConfig.get().runtime.output_dir) / FAILED)
            return float("nan")
        sys.exit(2)
    except Interrupted as e:  # the loop saved a checkpoint and said so in one line
        sys.exit(143 if e.signal_name == "SIGTERM" else 130)
    return metrics.get("temperature_rmse_K", metrics["deflection_rmse"])


if __name__ == "__main__":
    main()
