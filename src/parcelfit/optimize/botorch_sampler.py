"""BoTorch's noisy batch Bayesian optimisation behind the `Sampler` interface (optional extra).

``optimizer: {sampler: botorch}`` in a study file. The model and acquisition are BoTorch's
standard ones for noisy batch BO, used as BoTorch documents them:

* initial design: the same seeded Latin hypercube (16 points) as the ``gp`` sampler;
* model: ``SingleTaskGP`` on the space's unit cube (log-scale parameters already mapped, see
  `parcelfit.optimize.space`) with its default kernel and priors, the observation noise fitted
  by marginal likelihood (``fit_gpytorch_mll``), a ``Normalize`` input transform (bounds: the
  unit cube) and a ``Standardize`` outcome transform; the GP models the negative cost;
* acquisition: ``qLogNoisyExpectedImprovement`` over the evaluated points (quasi-Monte Carlo
  with ``mc_samples`` Sobol base samples), pending points (asked, not yet told) as
  ``X_pending``; a batch is optimised jointly by ``optimize_acqf`` (``num_restarts`` L-BFGS-B
  starts chosen from ``raw_samples`` points);
* failed evaluations (``cost=None``) are kept at the worst finite cost seen so far;
* the recommendation is the evaluated point with the lowest posterior mean cost.

Determinism: every ask runs with torch's random state forked and seeded with (seed, number of
observations, number of pending points), in double precision and on one thread, so the same
history gives the same batch whether it was lived or replayed (a resumed study).

Install: ``pip install "parcelfit[botorch]"``. Install PyTorch from its CPU wheel index first
(``pip install torch --index-url https://download.pytorch.org/whl/cpu``); the default index
brings a CUDA build of several GB.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping
from typing import Any

import numpy as np
from scipy.stats import qmc

from parcelfit.errors import ParcelfitError, missing_extra
from parcelfit.optimize.bo import settle_told
from parcelfit.optimize.space import Space


def _import_botorch() -> dict[str, Any]:
    """BoTorch's and PyTorch's parts used here, or the error that names the extra."""
    try:
        import torch
        from botorch.acquisition.logei import qLogNoisyExpectedImprovement
        from botorch.exceptions.warnings import BotorchWarning
        from botorch.fit import fit_gpytorch_mll
        from botorch.models import SingleTaskGP
        from botorch.models.transforms.input import Normalize
        from botorch.models.transforms.outcome import Standardize
        from botorch.optim import optimize_acqf
        from botorch.sampling.normal import SobolQMCNormalSampler
        from gpytorch.mlls import ExactMarginalLogLikelihood
    except ImportError as exc:
        raise missing_extra("botorch", exc, extra="botorch", what="the botorch optimizer") from exc
    return {
        "torch": torch,
        "qLogNEI": qLogNoisyExpectedImprovement,
        "BotorchWarning": BotorchWarning,
        "fit": fit_gpytorch_mll,
        "SingleTaskGP": SingleTaskGP,
        "Normalize": Normalize,
        "Standardize": Standardize,
        "optimize_acqf": optimize_acqf,
        "Sampler": SobolQMCNormalSampler,
        "MLL": ExactMarginalLogLikelihood,
    }


class BoTorchSampler:
    """BoTorch's SingleTaskGP and qLogNEI as a batch ask/tell optimiser that minimises a cost
    (see the module docstring)."""

    def __init__(
        self,
        space: Space,
        batch_size: int = 4,
        seed: int = 0,
        n_initial: int = 16,
        num_restarts: int = 8,
        raw_samples: int = 256,
        mc_samples: int = 128,
    ) -> None:
        self._bt = _import_botorch()
        if batch_size < 1 or n_initial < 1 or num_restarts < 1 or raw_samples < num_restarts:
            raise ParcelfitError(
                "invalid botorch settings: batch_size, n_initial and num_restarts must be >= 1 "
                f"and raw_samples >= num_restarts (got {batch_size}, {n_initial}, "
                f"{num_restarts}, {raw_samples})"
            )
        self.space = space
        self.batch_size = batch_size
        self.seed = seed
        self.num_restarts = num_restarts
        self.raw_samples = raw_samples
        self.mc_samples = mc_samples
        lhs = qmc.LatinHypercube(
            d=len(space), scramble=True, seed=np.random.default_rng([seed, 0xA11])
        )  # the gp sampler's initial design
        self._initial = list(lhs.random(n_initial))
        self._pending: list[np.ndarray] = []
        self._told: list[tuple[np.ndarray, dict[str, float], float | None]] = []

    # -- the Sampler interface -----------------------------------------------------------------
    @property
    def n_told(self) -> int:
        """How many evaluations were told."""
        return len(self._told)

    def ask(self, n: int | None = None) -> list[dict[str, float]]:
        """The next ``n`` parameter sets to evaluate (default: the batch size)."""
        n = self.batch_size if n is None else n
        out: list[np.ndarray] = []
        while self._initial and len(out) < n:
            out.append(self._initial.pop(0))
        if len(out) < n:
            out += self._suggest(n - len(out), [*self._pending, *out])
        self._pending += out
        return [self.space.from_unit(u) for u in out]

    def tell(self, params: Mapping[str, float], cost: float | None) -> None:
        """Report an evaluated parameter set's cost (None or non-finite: failed)."""
        u = self.space.to_unit(params)
        settle_told(u, self._pending, self._initial)
        ok = cost is not None and math.isfinite(cost)
        self._told.append((u, dict(params), float(cost) if ok else None))  # type: ignore[arg-type]

    def best(self) -> tuple[dict[str, float], float] | None:
        """The evaluated parameters with the lowest cost, and that cost."""
        ok = [(p, c) for _, p, c in self._told if c is not None]
        if not ok:
            return None
        p, c = min(ok, key=lambda t: t[1])  # type: ignore[arg-type, return-value]
        return dict(p), float(c)  # type: ignore[arg-type]

    def recommend(self) -> tuple[dict[str, float], float] | None:
        """Of the evaluated points, the one with the lowest posterior mean cost, with its
        observed cost (the best observed before the model can be fitted)."""
        best = self.best()
        ok = [(u, p, c) for u, p, c in self._told if c is not None]
        if best is None or len(ok) < 2:
            return best
        torch = self._bt["torch"]
        with self._deterministic(len(self._pending)):
            model = self._model()
            X = torch.tensor(np.array([u for u, _, _ in ok]), dtype=torch.double)
            with torch.no_grad():
                mean = model.posterior(X).mean.squeeze(-1).numpy()  # of the negative cost
        _, p, c = ok[int(np.argmax(mean))]
        return dict(p), float(c)  # type: ignore[arg-type]

    # -- internals -----------------------------------------------------------------------------
    def _state(self, n_pending: int) -> int:
        """The torch seed of an ask: from (seed, observations, pending points)."""
        seq = np.random.SeedSequence([self.seed, len(self._told), n_pending])
        return int(seq.generate_state(1, dtype=np.uint32)[0])

    def _deterministic(self, n_pending: int) -> _Deterministic:
        return _Deterministic(self._bt["torch"], self._state(n_pending), self._bt["BotorchWarning"])

    def _training_data(self) -> tuple[np.ndarray, np.ndarray]:
        """Unit-cube points and negative costs, failures at the worst finite cost."""
        finite = [c for _, _, c in self._told if c is not None]
        worst = max(finite) if finite else 0.0
        X = np.array([u for u, _, _ in self._told])
        y = -np.array([worst if c is None else c for _, _, c in self._told])
        return X, y

    def _model(self) -> Any:
        """The fitted SingleTaskGP (inside `_deterministic`)."""
        bt, torch = self._bt, self._bt["torch"]
        X, y = self._training_data()
        d = X.shape[1]
        train_X = torch.tensor(X, dtype=torch.double)
        train_Y = torch.tensor(y, dtype=torch.double).unsqueeze(-1)
        unit = torch.stack([torch.zeros(d, dtype=torch.double), torch.ones(d, dtype=torch.double)])
        model = bt["SingleTaskGP"](
            train_X,
            train_Y,
            input_transform=bt["Normalize"](d=d, bounds=unit),
            outcome_transform=bt["Standardize"](m=1),
        )
        bt["fit"](bt["MLL"](model.likelihood, model))
        return model

    def _suggest(self, n: int, pending: list[np.ndarray]) -> list[np.ndarray]:
        """``n`` new unit-cube points by qLogNEI given the pending points (random before two
        evaluations)."""
        bt, torch = self._bt, self._bt["torch"]
        d = len(self.space)
        state = self._state(len(pending))
        if len(self._told) < 2 or len({tuple(u) for u, _, _ in self._told}) < 2:
            rng = np.random.default_rng(state)
            return list(rng.random((n, d)))
        with self._deterministic(len(pending)):
            model = self._model()
            X, _ = self._training_data()
            acq = bt["qLogNEI"](
                model=model,
                X_baseline=torch.tensor(X, dtype=torch.double),
                sampler=bt["Sampler"](sample_shape=torch.Size([self.mc_samples]), seed=state),
                X_pending=torch.tensor(np.array(pending), dtype=torch.double) if pending else None,
                prune_baseline=True,
            )
            unit = torch.stack(
                [torch.zeros(d, dtype=torch.double), torch.ones(d, dtype=torch.double)]
            )
            cand, _ = bt["optimize_acqf"](
                acq,
                bounds=unit,
                q=n,
                num_restarts=self.num_restarts,
                raw_samples=self.raw_samples,
                options={"seed": state},
            )
        return [np.clip(row, 0.0, 1.0) for row in cand.detach().numpy()]


class _Deterministic:
    """Torch's random state forked and seeded, one thread, BoTorch's notices silenced; all
    restored on exit."""

    def __init__(self, torch: Any, seed: int, warning: type[Warning]) -> None:
        self.torch, self.seed, self.warning = torch, seed, warning

    def __enter__(self) -> None:
        torch = self.torch
        self._threads = torch.get_num_threads()
        torch.set_num_threads(1)
        self._fork = torch.random.fork_rng(devices=[])
        self._fork.__enter__()
        torch.manual_seed(self.seed)
        self._warnings = warnings.catch_warnings()
        self._warnings.__enter__()
        warnings.simplefilter("ignore", self.warning)
        warnings.simplefilter("ignore", RuntimeWarning)

    def __exit__(self, *exc: object) -> None:
        self._warnings.__exit__(*exc)
        self._fork.__exit__(*exc)
        self.torch.set_num_threads(self._threads)
