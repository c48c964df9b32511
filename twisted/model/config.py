"""The configurations of the inverse model and of its training, and the choices they take.

Kept apart from :mod:`twisted.model.network` and :mod:`twisted.model.train` (which import torch) so
that what reads them only to offer or check options (the CLI) stays light.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

from twisted.rope import DEFAULT_ROPE, ROPE, ROPE_ENV, RopeProfile

__all__ = ["DEVICES", "LINK_HEADS", "ModelRopeError", "NetConfig", "SOURCES", "TrainConfig"]

# "pointer": one scorer shared by the N_LINKS links reads the context and each link's token;
# "dense": N_LINKS logits straight from the context
LINK_HEADS = ("pointer", "dense")
# where training samples come from (twisted.model.data): collected transitions, planner tree edges
SOURCES = ("collect", "search")
# torch devices training runs on; "cuda:N" picks one GPU of several
DEVICES = ("cpu", "cuda")


@dataclass(frozen=True)
class NetConfig:
    """Architecture of :class:`twisted.model.network.InverseNet` (stored with every model so it can be
    rebuilt)."""

    hidden: int = 256
    layers: int = 3
    head_hidden: int = 128
    components: int = 4
    link_head: str = LINK_HEADS[0]  # one of LINK_HEADS
    # condition on where the next state's new crossing visits land on the current rope
    new_visits: bool = True
    # condition on the abstract move (R1 / R2 / Cross, segments, sides, over/under, sign)
    move: bool = True
    # the rope the network is made for (twisted.rope.ROPE of the process that built it): its shapes
    # follow the link count, and its inputs are scaled by the rope's length
    n_links: int = ROPE.n_links
    link_spacing_m: float = ROPE.link_spacing_m
    # the rope's crossing limit: the input has room for states of this many crossings
    max_crossings: int = ROPE.max_crossings

    @property
    def rope(self) -> RopeProfile:
        return RopeProfile(self.n_links, self.link_spacing_m, self.max_crossings)

    def check_rope(self) -> None:
        """Raise :class:`ModelRopeError` unless the network is for the rope this process runs."""
        if self.rope != ROPE:
            raise ModelRopeError(
                f"the model is for a rope of {self.rope.name} but this process runs a rope of {ROPE.name}: "
                f"run with {ROPE_ENV}={self.rope.env_value} to use it, or train one for this rope "
                "(`twisted train`)"
            )

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> NetConfig:
        # models stored before the move input had none; before ropes could differ (or name a crossing
        # limit), no rope: the default's
        legacy = {
            "move": False,
            "n_links": DEFAULT_ROPE.n_links,
            "link_spacing_m": DEFAULT_ROPE.link_spacing_m,
            "max_crossings": DEFAULT_ROPE.max_crossings,
        }
        d = {**legacy, **d}
        return cls(**{k: v for k, v in d.items() if k in cls.__dataclass_fields__})


class ModelRopeError(ValueError):
    """A model made for another rope than the one this process runs (``TWISTED_ROPE``)."""


@dataclass
class TrainConfig:
    """Hyper-parameters of a run (stored in ``training_runs.parameters``)."""

    epochs: int = 40
    hours: float | None = None
    batch_size: int = 256
    lr: float = 1e-3
    weight_decay: float = 0.0  # AdamW's decoupled decay (0: plain Adam, the reference)
    seed: int = 0
    val_fraction: float = 0.1
    augment: bool = True
    checkpoint_every_s: float = 30.0
    net: NetConfig = field(default_factory=NetConfig)
    # where the samples come from (SOURCES): collected transitions, planner trees
    sources: tuple[str, ...] = ("collect",)
    # the tree snapshot (newest search node id) of a run that reads "search"; set when it starts
    max_search_node_id: int | None = None
    # problem sets whose goals are kept from the model: the planner trees of runs towards them, and
    # every sample of either source that reaches one of their states (the runs a model is then
    # evaluated on would otherwise be in its own training data)
    hold_out_sets: tuple[str, ...] = ()
    # fine-tuning: start from this stored model's weights (and architecture) instead of a seeded
    # initialisation, so that what earlier data taught a model carries into training on new data
    init_model_id: int | None = None
    # the collected transitions that remove crossings train the model too (labelled by the state
    # reached, the removing move marked by encode_move); runs stored before this option had none
    removing: bool = True

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["net"] = self.net.to_dict()
        d["sources"] = list(self.sources)
        d["hold_out_sets"] = list(self.hold_out_sets)
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> TrainConfig:
        d = dict(d)
        net = NetConfig.from_dict(d.pop("net", {}))
        d["sources"] = tuple(d.get("sources", ("collect",)))
        d["hold_out_sets"] = tuple(d.get("hold_out_sets", ()))
        d.setdefault("removing", False)  # stored before the option: adding transitions only
        return cls(net=net, **{k: v for k, v in d.items() if k in cls.__dataclass_fields__})
