"""`python -m isac_mission.cli ARGS`: the `isac-mission` command."""

from isac_mission.cli import main

main()
