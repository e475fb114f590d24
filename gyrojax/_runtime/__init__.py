"""Running long jobs: what a long step reports while it works (`progress.py`: `Progress`, `as_progress`) and a stop
asked for by a signal, acted on at safe points (`stop.py`: `Interrupted`, `check`)."""
