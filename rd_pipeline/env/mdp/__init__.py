"""The tracking task's terms: what the policy acts on and sees, how it is rewarded and stopped,
the events that reset and randomize it, and the motion command it follows."""
