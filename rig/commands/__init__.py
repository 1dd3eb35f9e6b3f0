"""CLI sub-command groups, one module per group; registered in :data:`rig.cli._COMMANDS`."""
