//! Captions in HumanML3D's text-file form (`caption#word/POS ...#start#end`).
