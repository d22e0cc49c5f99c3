"""Network sizes and switches (SPEC section 4), a frozen dataclass like ``solar_jax.config``."""

import dataclasses
import typing


@dataclasses.dataclass(frozen=True)
class NetworkConfig:
    """Sizes of the SOLAR, Amorpheus and monolithic networks; defaults are SPEC section 4's."""

    width: int = 128
    """Transformer d_model; the per-agent encoder scales its output by sqrt(width)."""

    heads: int = 2
    """Attention heads per transformer layer; must divide ``width``."""

    feedforward: int = 256
    """Hidden size of each layer's ReLU feed-forward block."""

    num_layers: int = 3
    """Transformer layers. SOLAR: layer 0 is intra-synergy, the rest inter-synergy (1 + 2).
    Amorpheus uses the same count over agents."""

    transform_dim: int = 64
    """d of the action transformation: each of the 4 heads gets a scalar k1 and a (d-1)-vector
    e per agent. d = 1 (the reference README's value) zeroes every non-exemplar action."""

    transform_heads: int = 4
    """Heads s of the action transformation, averaged (SPEC section 4: 4)."""

    embedding_dim: int = 64
    """Width of each of the three traversal embedding tables (pre, in, post order)."""

    gate_hidden: int = 256
    """Hidden size of the transform's gate MLP (width + 4d -> gate_hidden -> ReLU -> 4)."""

    hard_mask: bool = False
    """False (the code's, default): layer 0 adds the soft bias log(Ŵ Ŵᵀ). True (the paper's
    text): layer 0 blocks attention across synergies instead."""

    paper_transform: bool = False
    """False (the code's, default): exemplar rows masked by membership, times a state gate.
    True (the paper's text): T's columns averaged over each cluster's members, no gate."""

    mlp_hidden: tuple[int, ...] = (400, 300)
    """Hidden sizes of the monolithic baseline's actor and critic MLPs (TD3's 400-300)."""

    init: typing.Literal["reference", "flax"] = "reference"
    """reference (default): the authors' PyTorch initialisation (SPEC section 4: encoder
    and decoder U(±0.1), PyTorch Linear defaults, xavier in-projection, embeddings
    N(0, 1), the layers of one network identical at init). flax: Flax's initialisers."""

    torso_action: bool = True
    """True (the reference): the actor outputs an action for the torso too, which the
    replay stores, the critic reads and target noise perturbs (the physics ignores it).
    False: the torso's action is zeroed everywhere."""

    def __post_init__(self):
        for name in (
            "width",
            "heads",
            "feedforward",
            "num_layers",
            "transform_dim",
            "transform_heads",
            "embedding_dim",
            "gate_hidden",
        ):
            if getattr(self, name) < 1:
                raise ValueError(f"network.{name} must be >= 1, got {getattr(self, name)}")
        if self.width % self.heads:
            raise ValueError(f"network.heads ({self.heads}) must divide width ({self.width})")
        if self.init not in typing.get_args(NetworkConfig.__annotations__["init"]):
            raise ValueError(f"network.init must be reference or flax, got {self.init!r}")
        if not self.mlp_hidden or min(self.mlp_hidden) < 1:
            raise ValueError(f"network.mlp_hidden must be positive sizes, got {self.mlp_hidden}")

    @classmethod
    def tiny(cls, **overrides) -> "NetworkConfig":
        """Small sizes for CPU smoke runs and tests (1 intra-synergy + 1 inter-synergy layer)."""
        sizes = dict(
            width=16,
            num_layers=2,
            heads=2,
            feedforward=32,
            transform_dim=4,
            embedding_dim=8,
            gate_hidden=16,
            mlp_hidden=(32, 32),
        )
        return cls(**(sizes | overrides))

    @classmethod
    def small(cls, **overrides) -> "NetworkConfig":
        """Between tiny and the paper's sizes, for CPU learning curves: the paper's three
        layers (1 intra + 2 inter) at a quarter of its widths, d = 8. Sized to cost at most
        ~3x tiny per TD3 iteration on 2 CPU cores (benchmarks/README.md, learner.py)."""
        sizes = dict(
            width=32,
            num_layers=3,
            heads=2,
            feedforward=64,
            transform_dim=8,
            embedding_dim=16,
            gate_hidden=64,
            mlp_hidden=(64, 64),
        )
        return cls(**(sizes | overrides))

    @classmethod
    def preset(cls, name: str) -> "NetworkConfig":
        """``net=``'s presets: default (SPEC section 4), small, tiny."""
        presets = {"default": cls, "small": cls.small, "tiny": cls.tiny}
        if name not in presets:
            raise ValueError(f"net={name}: expected one of {', '.join(presets)}")
        return presets[name]()
