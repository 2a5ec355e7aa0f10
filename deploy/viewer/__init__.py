"""Watching a swarm: the live page in the browser, replay of recordings, Foxglove live."""
