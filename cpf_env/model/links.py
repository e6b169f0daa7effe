"""Link impairments: what an imperfect link does to a packet.

Every directed link of the communication graph (``cpf_env.model.graph``) loses
each packet independently with probability ``loss_probability`` and delivers
the ones it keeps ``delay_steps`` control steps late; the simulator's message
exchange applies both, and the receiver sees the age of what it holds.

    >>> LinkImpairments(loss_probability=0.3, delay_steps=5).perfect
    False
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["LinkImpairments"]


@dataclass(frozen=True)
class LinkImpairments:
    """Imperfect links: independent packet loss and a fixed transport delay.

    Attributes:
        loss_probability: Probability in [0, 1) that a packet on one directed link is
            lost in one control step (independent Bernoulli draws).
        delay_steps: Transport delay in control steps (>= 0).
    """

    loss_probability: float = 0.0
    delay_steps: int = 0

    def __post_init__(self) -> None:
        p = float(self.loss_probability)
        if not 0.0 <= p < 1.0:
            raise ValueError(
                f"loss_probability must be in [0, 1), got {self.loss_probability}; with "
                "p = 1 no packet ever arrives."
            )
        d = int(self.delay_steps)
        if d != self.delay_steps or d < 0:
            raise ValueError(
                f"delay_steps must be a whole number of control steps >= 0, got {self.delay_steps}."
            )
        object.__setattr__(self, "loss_probability", p)
        object.__setattr__(self, "delay_steps", d)

    @property
    def perfect(self) -> bool:
        """True if links neither lose nor delay packets."""
        return self.loss_probability == 0.0 and self.delay_steps == 0
