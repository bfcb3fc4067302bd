"""Train a model: ``python train.py +experiment=wasb_padel`` (configs in conf/, see conf/train.yaml)."""
import os
from pathlib import Path

import hydra
from omegaconf import DictConfig

os.environ.setdefault("PROJECT_ROOT", str(Path(__file__).resolve().parent))


@hydra.main(version_base="1.3", config_path="conf", config_name="train")
def main(cfg: DictConfig) -> float | None:
    """Returns ``optimized_metric`` (default ``val/f1_best``; hit events ``events/val_f1``) to sweepers."""
    from training.preflight import check_data

    check_data(cfg)  # before torch and Lightning are imported: a missing dataset is made or named at once
    from training.run import optimized_metric, train

    return optimized_metric(cfg, train(cfg))


if __name__ == "__main__":
    main()
