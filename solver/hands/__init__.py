"""Hands: sphere sensors on the fingers and palm, and the interactive grasping automaton (Huang
1996, sec. 4.3 and 4.7). bpy-free."""
