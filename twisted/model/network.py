"""The auto-regressive inverse model p(c | q, s') = p(link) p(z | link) p(x | link, z) p(y | link, z, x).

Every factor is conditioned on a context vector computed from the configuration (canonical link
points and their crossings, :mod:`twisted.model.encoding`), the CURRENT P-data, the NEXT P-data,
when the next state is the current one plus new crossings the segments of the current rope where
the new crossing visits land (:func:`twisted.model.encoding.new_visits`), and the abstract MOVE that
makes the next state (R1 / R2 / Cross with its segments, sides, over/under and sign; the planner
has it from the plan, training derives it from the transition with :func:`twisted.moves.explains`).

``link`` is categorical over the N_LINKS links, scored by one small network shared by all links that
reads the context and the link's own token (its place, direction, crossings, P-data visits on it,
and whether a new visit lands on its segment): choosing "the link on segment 3" then does not have
to be learned separately for every link number. ``z``, ``x`` and ``y`` are each a small Gaussian
mixture in the normalised target space; their heads also see the chosen link (one-hot and token).

Training uses teacher forcing with the TRUE previous elements of the curve; sampling is ancestral.
A Gaussian mixture has mass outside the valid ranges; sampling re-draws the out-of-range elements
(``z`` outside [0, 0.07] m, or the world displacement outside [-0.5, 0.5] m on x or y once rotated
back from the canonical frame) up to :data:`MAX_REDRAWS` times and clips what is still outside,
so every sampled curve is valid. The NLL is that of the untruncated mixture.
"""

from __future__ import annotations

import io
import math
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np
import numpy.typing as npt
import torch
from torch import nn

from twisted.model.config import LINK_HEADS, NetConfig
from twisted.model.encoding import (
    GEOMETRY_DIM,
    LINK_TOKEN_DIM,
    MOVE_DIM,
    MOVE_LINK_DIM,
    NEW_DIM,
    NEW_LINK_DIM,
    P_DATA_DIM,
    Preprocessed,
    curve_to_target,
    curve_valid,
    encode_move,
    encode_new_visits,
    encode_p_data,
    move_link_features,
    new_visit_link_features,
    preprocess,
    target_to_curve,
)
from twisted.moves import Move, explains
from twisted.sim import CURVE_HIGH, CURVE_LOW, N_LINKS, Curve
from twisted.store.payloads import UnsafePayloadError, load_tensors
from twisted.topology import PData, parse_p_data, top

__all__ = ["Condition", "InverseModel", "InverseNet", "LINK_WEIGHT"]

# Bumped whenever inputs or layers change so that stored weights no longer fit; a stored model of
# another version is refused with a clear message instead of producing garbage.
FORMAT_VERSION = 1
# Sampling defaults measured on held-out transitions of the first collection (bench/success_at_6.py,
# 80 2->3 steps: success@6 0.125 with these against 0.062 with plain ancestral sampling).
DEFAULT_OVERSAMPLE = 8
DEFAULT_LINK_TEMPERATURE = 0.5
LINK_WEIGHT = 10.0  # loss = 10 x NLL(link) + NLL(z) + NLL(x) + NLL(y) (the reference's weighting)
MAX_REDRAWS = 32
LOG_STD_MIN, LOG_STD_MAX = -6.0, 1.0


def _mlp(sizes: list[int]) -> nn.Sequential:
    layers: list[nn.Module] = []
    for a, b in zip(sizes[:-2], sizes[1:-1], strict=True):
        layers += [nn.Linear(a, b), nn.SiLU()]
    layers.append(nn.Linear(sizes[-2], sizes[-1]))
    return nn.Sequential(*layers)


@dataclass
class Mixture:
    """Parameters of a batch of 1-D Gaussian mixtures, each (B, K)."""

    logits: torch.Tensor
    mean: torch.Tensor
    log_std: torch.Tensor

    def nll(self, x: torch.Tensor) -> torch.Tensor:
        """(B,) negative log-likelihood of values x (B,)."""
        z = (x[:, None] - self.mean) * torch.exp(-self.log_std)
        log_n = -0.5 * z * z - self.log_std - 0.5 * math.log(2 * math.pi)
        return -torch.logsumexp(torch.log_softmax(self.logits, dim=1) + log_n, dim=1)

    def sample(self, generator: torch.Generator | None) -> torch.Tensor:
        k = torch.multinomial(torch.softmax(self.logits, dim=1), 1, generator=generator)[:, 0]
        rows = torch.arange(len(k))
        eps = torch.randn(len(k), generator=generator, dtype=self.mean.dtype)
        return self.mean[rows, k] + torch.exp(self.log_std[rows, k]) * eps

    def rows(self, mask: torch.Tensor) -> Mixture:
        return Mixture(self.logits[mask], self.mean[mask], self.log_std[mask])


class MixtureHead(nn.Module):
    def __init__(self, in_dim: int, hidden: int, components: int) -> None:
        super().__init__()
        self.components = components
        self.net = _mlp([in_dim, hidden, hidden, 3 * components])

    def forward(self, x: torch.Tensor) -> Mixture:
        logits, mean, log_std = self.net(x).split(self.components, dim=1)
        return Mixture(logits, mean, log_std.clamp(LOG_STD_MIN, LOG_STD_MAX))


@dataclass
class Condition:
    """What a curve is conditioned on, besides the geometry: encoded current and next P-data
    (B, P_DATA_DIM), where the next state's new visits land (B, NEW_DIM) and the move (B, MOVE_DIM)."""

    p_now: torch.Tensor
    p_next: torch.Tensor
    new: torch.Tensor
    move: torch.Tensor

    def expand(self, n: int) -> Condition:
        return Condition(*(t.expand(n, -1) for t in (self.p_now, self.p_next, self.new, self.move)))


class LinkScorer(nn.Module):
    """Logit of each link from the context and that link's token, with weights shared by the links.

    The context part of the first layer is computed once per sample, not once per link.
    """

    def __init__(self, context_dim: int, token_dim: int, hidden: int) -> None:
        super().__init__()
        self.from_context = nn.Linear(context_dim, hidden)
        self.from_token = nn.Linear(token_dim, hidden, bias=False)
        self.out = nn.Sequential(nn.SiLU(), nn.Linear(hidden, hidden), nn.SiLU(), nn.Linear(hidden, 1))

    def forward(self, ctx: torch.Tensor, tokens: torch.Tensor) -> torch.Tensor:
        return self.out(self.from_context(ctx)[:, None] + self.from_token(tokens))[..., 0]


class InverseNet(nn.Module):
    """The network; inputs are already encoded (:class:`Preprocessed`, :class:`Condition`)."""

    def __init__(self, config: NetConfig | None = None) -> None:
        super().__init__()
        self.config = config = config or NetConfig()
        config.check_rope()  # its shapes follow the link count: one of another rope cannot run here
        h = config.hidden
        new_dim = (NEW_DIM if config.new_visits else 0) + (MOVE_DIM if config.move else 0)
        self.token_dim = LINK_TOKEN_DIM + (NEW_LINK_DIM if config.new_visits else 0)
        self.token_dim += MOVE_LINK_DIM if config.move else 0
        self.trunk = nn.Sequential(
            _mlp([GEOMETRY_DIM + 2 * P_DATA_DIM + new_dim] + [h] * config.layers), nn.SiLU(), nn.LayerNorm(h)
        )
        if config.link_head not in LINK_HEADS:
            raise ValueError(f"link_head must be one of {', '.join(LINK_HEADS)}, got {config.link_head!r}")
        if config.link_head == "pointer":
            self.link_head: nn.Module = LinkScorer(h, self.token_dim, config.head_hidden)
        else:
            self.link_head = _mlp([h, config.head_hidden, N_LINKS])
        # one-hot link, that link's token, every link centre relative to it (where the other strands are)
        link_dim = N_LINKS + self.token_dim + 2 * N_LINKS
        self.z_head = MixtureHead(h + link_dim, config.head_hidden, config.components)
        self.x_head = MixtureHead(h + link_dim + 1, config.head_hidden, config.components)
        self.y_head = MixtureHead(h + link_dim + 2, config.head_hidden, config.components)

    def context(self, pre: Preprocessed, cond: Condition) -> torch.Tensor:
        """(B, hidden) context from the geometry and the condition."""
        parts = [pre.features, cond.p_now, cond.p_next] + ([cond.new] if self.config.new_visits else [])
        parts += [cond.move] if self.config.move else []
        return self.trunk(torch.cat(parts, dim=1))

    def tokens(self, pre: Preprocessed, cond: Condition) -> torch.Tensor:
        """(B, N_LINKS, token_dim): each link's geometry, whether the next state's new visits land on it,
        and whether it lies on the move's segments."""
        parts = [pre.link_tokens]
        if self.config.new_visits:
            parts.append(new_visit_link_features(pre, cond.new))
        if self.config.move:
            parts.append(move_link_features(pre, cond.move))
        return parts[0] if len(parts) == 1 else torch.cat(parts, dim=2)

    def _link_logits(self, ctx: torch.Tensor, tokens: torch.Tensor) -> torch.Tensor:
        if self.config.link_head == "pointer":
            return self.link_head(ctx, tokens)
        return self.link_head(ctx)

    @staticmethod
    def _link_features(ctx: torch.Tensor, tokens: torch.Tensor, link: torch.Tensor) -> torch.Tensor:
        one_hot = nn.functional.one_hot(link, N_LINKS).to(ctx.dtype)
        token = tokens[torch.arange(len(link), device=link.device), link]
        relative = tokens[:, :, :2] - token[:, None, :2]  # canonical link centres minus the grasped one
        return torch.cat([ctx, one_hot, token, relative.flatten(1)], dim=1)

    def losses(self, pre: Preprocessed, cond: Condition, curve: torch.Tensor) -> dict[str, torch.Tensor]:
        """Per-sample NLL terms (B,) with teacher forcing on the TRUE link, z and x of ``curve`` (B, 4)."""
        link, target = curve_to_target(curve, pre)
        ctx = self.context(pre, cond)
        tokens = self.tokens(pre, cond)
        lf = self._link_features(ctx, tokens, link)
        nll_link = nn.functional.cross_entropy(self._link_logits(ctx, tokens), link, reduction="none")
        nll_z = self.z_head(lf).nll(target[:, 0])
        nll_x = self.x_head(torch.cat([lf, target[:, :1]], dim=1)).nll(target[:, 1])
        nll_y = self.y_head(torch.cat([lf, target[:, :2]], dim=1)).nll(target[:, 2])
        loss = LINK_WEIGHT * nll_link + nll_z + nll_x + nll_y
        return {"loss": loss, "nll_link": nll_link, "nll_z": nll_z, "nll_x": nll_x, "nll_y": nll_y}

    def link_logits(self, pre: Preprocessed, cond: Condition) -> torch.Tensor:
        return self._link_logits(self.context(pre, cond), self.tokens(pre, cond))

    @torch.no_grad()
    def log_prob(self, pre: Preprocessed, cond: Condition, curve: torch.Tensor) -> torch.Tensor:
        """(B,) joint log-density of world curves (B, 4) in the normalised target space."""
        terms = self.losses(pre, cond, curve.to(pre.features.dtype))
        return -(terms["nll_link"] + terms["nll_z"] + terms["nll_x"] + terms["nll_y"])

    @torch.no_grad()
    def sample(
        self,
        pre: Preprocessed,
        cond: Condition,
        generator: torch.Generator | None,
        link_temperature: float = 1.0,
    ) -> torch.Tensor:
        """Ancestral sampling of one valid world curve (B, 4) float64 per row (see the module docstring).

        ``link_temperature`` < 1 sharpens the link distribution (logits divided by it).
        """
        ctx = self.context(pre, cond)
        tokens = self.tokens(pre, cond)
        probs = torch.softmax(self._link_logits(ctx, tokens) / link_temperature, dim=1)
        link = torch.multinomial(probs, 1, generator=generator)[:, 0]
        lf = self._link_features(ctx, tokens, link)
        target = torch.zeros(len(link), 3)
        target[:, 0] = _sample_within_unit(self.z_head(lf), generator)
        # x then y, redrawing both where the rotated-back displacement leaves the box
        bad = torch.ones(len(link), dtype=torch.bool)
        for _ in range(MAX_REDRAWS):
            rows = bad.nonzero()[:, 0]
            if len(rows) == 0:
                break
            lfz = torch.cat([lf[rows], target[rows, :1]], dim=1)
            target[rows, 1] = self.x_head(lfz).sample(generator)
            target[rows, 2] = self.y_head(torch.cat([lfz, target[rows, 1:2]], dim=1)).sample(generator)
            bad = ~curve_valid(target_to_curve(link, target, pre))
        # float64 so the clipped bounds are exactly the valid range
        curve = target_to_curve(link, target.double(), _double(pre))
        low = torch.as_tensor(CURVE_LOW, dtype=torch.float64)
        high = torch.as_tensor(CURVE_HIGH, dtype=torch.float64)
        return torch.maximum(torch.minimum(curve, high), low)


def _double(pre: Preprocessed) -> Preprocessed:
    return replace(pre, centre=pre.centre.double(), cos=pre.cos.double(), sin=pre.sin.double())


def astuple_shallow(pre: Preprocessed) -> tuple[torch.Tensor, ...]:
    """The tensors of ``pre`` in field order (dataclasses.astuple would deep-copy them)."""
    return tuple(getattr(pre, f.name) for f in fields(pre))


def _sample_within_unit(mix: Mixture, generator: torch.Generator | None) -> torch.Tensor:
    """Draws in [-1, 1]: out-of-range draws are redrawn, then clipped."""
    value = mix.sample(generator)
    for _ in range(MAX_REDRAWS):
        bad = value.abs() > 1.0
        if not bad.any():
            break
        value[bad] = mix.rows(bad).sample(generator)
    return value.clamp(-1.0, 1.0)


@dataclass
class InverseModel:
    """A trained :class:`InverseNet` with its metadata; what the planner uses.

    ``metadata`` holds the training run, data size, metrics and the command that trained it.
    """

    net: InverseNet
    metadata: dict[str, Any] = field(default_factory=dict)
    model_id: int | None = None
    # Sampling: draw `oversample` x n candidates and keep the n most likely under the model (1 =
    # plain ancestral sampling); link logits divided by `link_temperature`. Taken from
    # metadata["sampling"] when present, else DEFAULT_OVERSAMPLE / DEFAULT_LINK_TEMPERATURE.
    oversample: int | None = None
    link_temperature: float | None = None

    def __post_init__(self) -> None:
        self.net.eval()
        self._cache: dict[tuple[str, str, str | None], Condition] = {}
        sampling = self.metadata.get("sampling", {})
        if self.oversample is None:
            self.oversample = int(sampling.get("oversample", DEFAULT_OVERSAMPLE))
        if self.link_temperature is None:
            self.link_temperature = float(sampling.get("link_temperature", DEFAULT_LINK_TEMPERATURE))
        if self.oversample < 1 or not self.link_temperature > 0:
            raise ValueError(
                "oversample must be >= 1 and link_temperature > 0, "
                f"got {self.oversample} and {self.link_temperature}"
            )

    def unusable(self) -> str | None:
        """Why this model cannot plan (NaN or infinite weights or losses, or a forward pass on the
        straight rope that gives non-finite probabilities or curves), in words; None when it can.

        What an imported model must pass before it is stored, as a trained one is checked."""
        for name, values in self.net.state_dict().items():
            if torch.is_floating_point(values) and not bool(torch.isfinite(values).all()):
                return f"its weights {name} hold NaN or infinity"
        metrics = self.metadata.get("metrics", {}) or {}
        for name in ("val_loss", "train_loss"):
            value = metrics.get(name) if isinstance(metrics, dict) else None
            if value is not None and not (isinstance(value, (int, float)) and math.isfinite(value)):
                return f"its {name.replace('_', ' ')} is {value}"
        straight = np.stack(
            [np.linspace(-0.5, 0.5, N_LINKS + 1), np.zeros(N_LINKS + 1), np.full(N_LINKS + 1, 0.01)], 1
        )
        goal = parse_p_data('[[1,"O",2,"+"],[2,"U",1,"+"]]')
        try:
            probs = self.link_probabilities(straight, goal)
            if not (np.all(np.isfinite(probs)) and abs(float(probs.sum()) - 1.0) < 1e-3):
                return "its forward pass on the straight rope gives link probabilities that are not finite"
            curves = self.sample(straight, None, goal, 4, np.random.default_rng(0))
        except (ValueError, RuntimeError, FloatingPointError) as exc:
            return f"its forward pass on the straight rope fails ({type(exc).__name__}: {exc})"
        if not all(np.all(np.isfinite(c.to_array())) for c in curves):
            return "its forward pass on the straight rope gives curves that are not finite"
        return None

    def condition(self, p_now: PData, p_next: PData, move: Move | None = None) -> Condition:
        """The encoded condition (batch of one) for going from ``p_now`` to ``p_next`` by ``move``
        (default: the first move that does it, :func:`twisted.moves.explains`, as in training); cached."""
        key = (p_now.key, p_next.key, None if move is None else str(move))
        cond = self._cache.get(key)
        if cond is None:
            if move is None and self.net.config.move:
                move = explains(p_now, p_next)
            cond = Condition(
                torch.from_numpy(encode_p_data(p_now))[None],
                torch.from_numpy(encode_p_data(p_next))[None],
                torch.from_numpy(encode_new_visits(p_now, p_next))[None],
                torch.from_numpy(encode_move(move))[None],
            )
            if len(self._cache) > 100_000:
                self._cache.clear()
            self._cache[key] = cond
        return cond

    @torch.no_grad()
    def sample(
        self,
        points: npt.ArrayLike,
        q: npt.ArrayLike | None,
        next_p_data: PData | str | list[Any],
        n: int,
        rng: np.random.Generator,
        *,
        p_data: PData | None = None,
        move: Move | None = None,
    ) -> list[Curve]:
        """``n`` curves meant to take the rope at ``points`` (N_POINTS, 3) to the state ``next_p_data``.

        ``q`` is accepted for the planner's contract but not read: the settled rope is described
        by its link points (capsules are symmetric about their axis; velocities are near zero).
        ``p_data`` is the current state; computed with ``top(points)`` when omitted. ``move`` is the
        abstract move meant to make ``next_p_data`` (the plan's); by default the first that does. Draws come
        from a torch generator seeded from ``rng``, so a seeded ``rng`` replays the same curves.
        With ``oversample`` > 1 the n most likely of ``oversample * n`` draws are returned.
        """
        del q
        pts = np.asarray(points, dtype=np.float64)
        nxt = parse_p_data(next_p_data)
        now = top(pts) if p_data is None else p_data
        assert self.oversample is not None and self.link_temperature is not None
        m = n * self.oversample
        cond = self.condition(now, nxt, move).expand(m)
        pre = preprocess(pts)
        pre_m = Preprocessed(*(t.expand(m, *t.shape[1:]) for t in astuple_shallow(pre)))
        generator = torch.Generator().manual_seed(int(rng.integers(0, 2**63 - 1)))
        curves = self.net.sample(pre_m, cond, generator, self.link_temperature)
        if self.oversample > 1:
            best = self.net.log_prob(pre_m, cond, curves).argsort(descending=True, stable=True)[:n]
            curves = curves[best]
        return [Curve.from_array(c) for c in curves.numpy()]

    @torch.no_grad()
    def link_probabilities(
        self, points: npt.ArrayLike, next_p_data: PData, p_data: PData | None = None, move: Move | None = None
    ) -> np.ndarray:
        """(N_LINKS,) probability of each link being the one to grasp."""
        pts = np.asarray(points, dtype=np.float64)
        now = top(pts) if p_data is None else p_data
        logits = self.net.link_logits(preprocess(pts), self.condition(now, parse_p_data(next_p_data), move))
        return torch.softmax(logits, dim=1)[0].numpy()

    def to_bytes(self) -> bytes:
        """torch.save of the weights, architecture and metadata (what the store's BLOB holds)."""
        buffer = io.BytesIO()
        torch.save(
            {
                "format_version": FORMAT_VERSION,
                "config": self.net.config.to_dict(),
                "state_dict": self.net.state_dict(),
                "metadata": self.metadata,
            },
            buffer,
        )
        return buffer.getvalue()

    @classmethod
    def from_bytes(cls, data: bytes, model_id: int | None = None) -> InverseModel:
        blob = load_tensors(data, "the inverse model")  # tensors and plain data only (docs/security.md)
        if not isinstance(blob, dict) or not {"config", "state_dict"} <= set(blob):
            raise UnsafePayloadError("the inverse model is not one written by twisted (no config, weights)")
        version = int(blob.get("format_version", 1))
        if version != FORMAT_VERSION:
            raise ValueError(
                f"this inverse model was saved in format {version}, this version of twisted reads format "
                f"{FORMAT_VERSION}: train a new one with `twisted train`"
            )
        config = _declared_config(blob["config"], blob["state_dict"])
        net = InverseNet(config)
        net.load_state_dict(blob["state_dict"])
        return cls(net=net, metadata=dict(blob.get("metadata", {})), model_id=model_id)


def _declared_config(stored: Any, state_dict: Any) -> NetConfig:
    """The architecture a stored model declares, checked against its weights before the network is built.

    The network is first made on the meta device (no memory), and every stored tensor must have the
    shape and dtype it declares: the real network, built next, is then exactly as large as the weights
    the payload holds (:func:`twisted.store.payloads.load_tensors` bounded those by the row's size).
    Raises :class:`UnsafePayloadError` otherwise.
    """
    if not isinstance(stored, dict) or not isinstance(state_dict, dict):
        raise UnsafePayloadError("the inverse model's config and weights are not mappings")
    try:
        config = NetConfig.from_dict(stored)
    except TypeError as exc:
        raise UnsafePayloadError(f"the inverse model's config cannot be read ({exc})") from None
    sizes = {name: getattr(config, name) for name in ("hidden", "layers", "head_hidden", "components")}
    bad = next((n for n, v in sizes.items() if type(v) is not int or v < 1), None)
    if bad is not None:
        raise UnsafePayloadError(f"the inverse model's config has {bad} = {str(sizes[bad])[:40]!r}")
    if config.layers > len(state_dict):  # each layer holds weights: more layers than tensors cannot fit
        raise UnsafePayloadError(
            f"the inverse model's config declares {config.layers:,} layers but it holds "
            f"{len(state_dict):,} tensors"
        )
    with torch.device("meta"):
        declared = {k: (tuple(v.shape), v.dtype) for k, v in InverseNet(config).state_dict().items()}
    held = {
        k: (tuple(v.shape), v.dtype) if isinstance(v, torch.Tensor) else None for k, v in state_dict.items()
    }
    if held != declared:
        odd = sorted(str(k)[:60] for k in set(held) ^ set(declared))[:3] or [
            str(k)[:60] for k in declared if held.get(k) != declared[k]
        ][:3]
        raise UnsafePayloadError(
            f"the inverse model's weights do not fit the architecture its config declares (first: {odd})"
        )
    return config
