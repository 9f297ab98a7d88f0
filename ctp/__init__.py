"""The command line on top of everything: ``ctp analyze | modes | simulate | plan | batch | schema``."""
