"""The robot: its decision controller and everything a port to hardware needs."""
