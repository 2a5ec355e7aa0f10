"""Who may do what in a run: run keys, TLS certificates, Zenoh access control, and the
janitor that removes a run's private files."""
