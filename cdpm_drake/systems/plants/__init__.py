"""The simulated plants behind the controller's reel ports: the kinematic reels with the
person at the handle (`!SimulatedReels`) and the dynamic plant (`!DynamicReels`)."""
