"""SMP, Shared Modular Policies (Huang et al., 2020): the paper's message-passing baseline
(algorithm.md §4), as the Amorpheus code base runs it with both passes on.

One set of modules serves every limb of every morphology. Bottom-up, each limb sends its
parent a message (``message_dim``, L2-normalised) from its observation (the critic: and
its action) and its children's messages, concatenated by birth order and zero-padded to
``max_children``. Top-down, each limb reads one slot of its parent's message (the torso:
zeros) beside its own bottom-up message, and gives its action (the critic: twin Q, one
per limb) and a message for each child.

Trees of different shapes run in one program, level by level, as static shapes built
from each morphology's ``Tree``. Bottom-up: L + 1 rounds of every limb at once (a
limb's message is final once its children's are; the bottom-up module is small), its
children's messages gathered by a one-hot route ``[N, C, N]``. Top-down: one round per
depth that has parents (L), each running the large message MLP on that depth's parents
only (``senders``, [W_d] per depth, padded to the suite's widest at that depth) and
routing each result to the children's slots. Padded agents have no parent and no
children; their outputs are zeroed.
"""

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from solar_jax.config import NetworkConfig
from solar_jax.morphology.graph import depths
from solar_jax.networks.common import DIAGNOSTICS, MLP, mask_actions, mask_inputs

NORM_EPS = 1e-12  # torch.nn.functional.normalize's


@struct.dataclass
class Tree:
    """One morphology's limb tree, padded to N (a leading ``[M]`` when stacked)."""

    parents: jax.Array  # [N] int32: each limb's parent; -1 for the torso and padding
    sibling: jax.Array  # [N] int32: birth order among its parent's children (its bottom-up slot)
    down_slot: jax.Array  # [N] int32: the slot of its parent's top-down message it reads
    senders: tuple[jax.Array, ...]  # per depth [W_d] int32: the limbs with children; -1 pads


def _senders(parents: np.ndarray) -> list[list[int]]:
    """The limbs with children, by depth (torso first)."""
    depth, parent_set = depths(parents), set(parents[1:].tolist())
    by_depth = [np.flatnonzero(depth == d) for d in range(depth.max())]
    return [[int(i) for i in limbs if i in parent_set] for limbs in by_depth]


def make_tree(
    parents,
    n_max: int,
    max_children: int,
    flipped: bool = False,
    widths: tuple[int, ...] | None = None,
) -> Tree:
    """The ``Tree`` of a pre-order parent list, padded to ``n_max`` limbs and its senders
    to ``widths``, one per depth (None: its own). ``flipped``: the reference's flipped
    walkers, whose first limb reads the torso's message slots in reverse
    (``top_down_transmission``; the other limbs do not)."""
    parents = np.asarray(parents, np.int32)
    n = len(parents)
    if n > n_max:
        raise ValueError(f"a tree of {n} limbs does not fit n_max = {n_max}")
    sibling = np.array([np.sum(parents[:i] == p) for i, p in enumerate(parents)], np.int32)
    sibling[0] = -1  # the torso: no parent
    if n > 1 and sibling.max() >= max_children:
        raise ValueError(f"a limb has {sibling.max() + 1} children, more than {max_children}")
    down_slot = sibling.copy()
    if flipped and n > 1:
        down_slot[1] = max_children - 1 - sibling[1]
    own = _senders(parents)
    widths = tuple(map(len, own)) if widths is None else tuple(widths)
    if len(own) > len(widths) or any(len(s) > w for s, w in zip(own, widths, strict=False)):
        raise ValueError(f"a tree's senders {own} do not fit widths {widths}")
    own += [[]] * (len(widths) - len(own))
    senders = tuple(
        jnp.asarray(limbs + [-1] * (w - len(limbs)), jnp.int32)
        for limbs, w in zip(own, widths, strict=True)
    )

    def padded(x):
        return jnp.asarray(np.concatenate([x, np.full(n_max - n, -1, np.int32)]), jnp.int32)

    return Tree(padded(parents), padded(sibling), padded(down_slot), senders)


def limb_trees(parents: list, names: list[str], n_max: int) -> tuple[Tree, int]:
    """(every morphology's ``Tree``, stacked; the most children of any limb, at least 1):
    what SMP's messages are built for, over the whole suite, held-out robots included
    (the reference counts its training robots' children: the same for every suite here).
    Flipped walkers (``walker_N_flipped``) flip their first limb's slot, as the
    reference reads its file names."""
    children = max(max(np.bincount(np.asarray(p[1:]), minlength=1), default=0) for p in parents)
    children = max(int(children), 1)
    senders = [_senders(np.asarray(p)) for p in parents]
    widths = tuple(
        max(len(own[d]) for own in senders if d < len(own)) for d in range(max(map(len, senders)))
    )
    trees = [
        make_tree(p, n_max, children, "walker" in name and "flipped" in name, widths)
        for p, name in zip(parents, names, strict=True)
    ]
    return jax.tree.map(lambda *x: jnp.stack(x), *trees), children


def up_route(tree: Tree, agent_mask: jax.Array, max_children: int) -> jax.Array:
    """``[N, C, N]`` float: ``[n, j, i]`` = 1 where limb i is limb n's j-th child."""
    n = agent_mask.shape[-1]
    child = (tree.parents[None, :] == jnp.arange(n)[:, None]) & agent_mask[None, :]  # [n, i]
    slots = jnp.arange(max_children)[None, :, None]
    return (child[:, None, :] & (tree.sibling[None, None, :] == slots)).astype(jnp.float32)


def l2_normalise(x: jax.Array) -> jax.Array:
    return x / jnp.maximum(jnp.linalg.norm(x, axis=-1, keepdims=True), NORM_EPS)


class BottomUp(nn.Module):
    """``x`` ``[B, N, F]`` -> each limb's bottom-up message ``[B, N, M]``: fc1, normalise,
    with the children's messages tanh, fc2, tanh, fc3, normalise (``ActorUp``,
    ``CriticUp``), ``rounds`` times over every limb."""

    config: NetworkConfig
    max_children: int

    @nn.compact
    def __call__(self, x: jax.Array, tree: Tree, agent_mask: jax.Array) -> jax.Array:
        c = self.config
        route = up_route(tree, agent_mask, self.max_children)
        own = l2_normalise(nn.Dense(c.message_width, name="fc1")(x))
        fc2 = nn.Dense(c.message_width, name="fc2")
        fc3 = nn.Dense(c.message_dim, name="fc3")
        messages = jnp.zeros((*x.shape[:2], c.message_dim), x.dtype)
        for _ in range(len(tree.senders) + 1):  # the deepest limb's depth + 1
            children = jnp.einsum("nji,bim->bnjm", route, messages)
            children = children.reshape(*children.shape[:2], -1)  # [B, N, C·M] by slot
            z = jnp.tanh(jnp.concatenate([own, children], -1))
            messages = l2_normalise(fc3(jnp.tanh(fc2(z))))
        return messages


def top_down(message_base: nn.Module, up: jax.Array, tree: Tree, max_children: int) -> jax.Array:
    """Each limb's slot of its parent's top-down message ``[B, N, M]`` (zeros for the
    torso): depth by depth, ``message_base`` on tanh([own bottom-up message, slot read])
    of that depth's senders ``[B, W, ·]`` only, each result routed to its children."""
    b, _, m = up.shape
    slot = jnp.zeros_like(up)
    slots = jnp.arange(max_children)[None, :, None]
    for senders in tree.senders:  # [W_d] per depth
        at = jnp.maximum(senders, 0)
        x = jnp.tanh(jnp.concatenate([up[:, at], slot[:, at]], -1))
        down = l2_normalise(message_base(x)).reshape(b, len(senders), max_children, m)
        # [W, C, N]: receiver i reads slot j of sender w
        route = (tree.parents[None, :] == senders[:, None]) & (senders[:, None] >= 0)
        route = route[:, None, :] & (tree.down_slot[None, None, :] == slots)
        slot = slot + jnp.einsum("wji,bwjm->bim", route.astype(up.dtype), down)
    return slot


class SmpActor(nn.Module):
    """``obs`` ``[B, N, 19]`` -> actions ``[B, N]`` (tanh; padding, and the torso without
    ``torso_action``, 0)."""

    config: NetworkConfig
    max_children: int

    @nn.compact
    def __call__(
        self,
        obs: jax.Array,
        agent_mask: jax.Array,
        synergy=None,
        traversal=None,
        tree: Tree | None = None,
    ) -> jax.Array:
        del synergy, traversal  # the interface's; SMP reads the tree only
        c = self.config
        x = mask_inputs(obs, agent_mask)
        up = BottomUp(c, self.max_children, name="up")(x, tree, agent_mask)
        message_base = MLP((*c.mlp_hidden, c.message_dim * self.max_children), name="msg_base")
        slot = top_down(message_base, up, tree, self.max_children)
        own = jnp.tanh(jnp.concatenate([up, slot], -1))
        out = MLP((*c.mlp_hidden, 1), name="action_base")(own)[..., 0]
        self.sow(DIAGNOSTICS, "pre_tanh", out)
        return mask_actions(jnp.tanh(out), agent_mask, c.torso_action)


class SmpCritic(nn.Module):
    """(``obs``, ``action``) -> per-limb Q ``[2, B, N]`` from one message-passing network
    with two Q heads (``CriticGraphPolicy``: the twins share their messages), or ``[B, N]``
    from the first head alone (``twin=False``: the reference's ``Q1``); 0 for padded
    limbs. Padded actions (and the torso's, without ``torso_action``) are zeroed first."""

    config: NetworkConfig
    max_children: int
    twin: bool = True

    @nn.compact
    def __call__(
        self,
        obs: jax.Array,
        action: jax.Array,
        agent_mask: jax.Array,
        synergy=None,
        tree: Tree | None = None,
    ) -> jax.Array:
        del synergy
        c = self.config
        action = mask_actions(action, agent_mask, c.torso_action)[..., None]
        x = mask_inputs(jnp.concatenate([obs, action], -1), agent_mask)
        up = BottomUp(c, self.max_children, name="up")(x, tree, agent_mask)
        message_base = MLP((*c.mlp_hidden, c.message_dim * self.max_children), name="msg_base")
        slot = top_down(message_base, up, tree, self.max_children)
        heads = ("q1", "q2") if self.twin else ("q1",)
        inputs = jnp.concatenate([up, action, slot], -1)
        q = jnp.stack([MLP((*c.mlp_hidden, 1), name=h)(inputs)[..., 0] for h in heads])
        q = jnp.where(agent_mask, q, 0.0)
        return q if self.twin else q[0]
