"""The sub-commands of `vibrofmu`, one module each. Every module exports `COMMAND`, a common.Command (name,
help, options, run); cli.py lists the modules in COMMANDS and does nothing else. A new command is one module
here and one line there."""
