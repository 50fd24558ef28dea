"""``python -m fsw --config FSW_FILE``: the flight process the SIL launches; its arguments are `cli.fsw`'s."""
from cli.fsw import main
raise SystemExit(main())
