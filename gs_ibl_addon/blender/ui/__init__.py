"""What the user sees and sets: the properties, the sidebar panels and their operators."""
