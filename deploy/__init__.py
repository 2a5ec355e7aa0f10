"""The `swarm` command: launcher, reports, and deployment configurations."""
