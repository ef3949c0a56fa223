"""Missions: the paper's dive types as generators and the ``auvnav-mission/1`` file
(:mod:`auvnav.plan.missions`)."""
