"""Controllers from outside the core: ``python:`` classes in a host process of their own and
``cmd:`` programs over the JSON-lines protocol (external, host), the Gymnasium environments
(gym), and a built-in controller served to another simulator (stage: the Stage round trip)."""
