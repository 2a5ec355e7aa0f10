"""``swarm conformance``: a port checked tick by tick against the controller vectors, over
its link, then in a lockstep swarm beside emulated robots (docs/porting.md)."""
