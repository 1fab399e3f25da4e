#!/usr/bin/env python3
"""Aggregate `perf script -F sym,ip` output of a `perf record --call-graph dwarf` run:
share of samples per leaf category (GEMM, libm, memcpy, page faults, own loops) and per
owning layer (innermost policy:: frame). Used for docs/bench/learner_profile.md."""
import sys, re, collections
# aggregate perf script samples: leaf category x owning layer
cur=[]; samples=[]
for line in open(sys.argv[1], errors='ignore'):
    line=line.rstrip('\n')
    if not line.strip():
        if cur: samples.append(cur); cur=[]
        continue
    if line.startswith((' ','\t')):
        m=re.match(r'\s+[0-9a-f]+\s+(.*?)(\s+\(inlined\))?$', line)
        if m: cur.append(m.group(1))
    else:
        if cur: samples.append(cur)
        cur=[]
if cur: samples.append(cur)
def layer(st):
    skip=('policy::nn::gemm','policy::nn::dot','policy::nn::attention::axpy','policy::nn::relu','policy::nn::tanh','policy::nn::sized','policy::nn::gru::sigmoid','policy::nn::gru::sized','policy::nn::attention::sized','<f32>','policy::nn::attention::dot','policy::nn::attention::sized','core::','alloc::','std::')
    for f in st:
        if f.startswith('policy::') and not f.startswith(skip) and '{{closure}}' not in f.split('::')[-1]:
            return re.sub(r'\s*\(inlined\)','',f)
    return '?'
def leaf(st):
    pre=[]
    for x in st:
        if x.startswith('policy::'): break
        pre.append(x)
    f=' '.join(pre) if pre else (st[0] if st else '?')
    if 'page_fault' in f: return 'kernel (page faults)'
    if 'matrixmultiply' in f: return 'GEMM (matrixmultiply)'
    if 'gemm::small' in f: return 'GEMM (small-k loop)'
    if re.search(r'exp|tanh|log', f): return 'libm exp/tanh'
    if re.search(r'mem(move|cpy|set)', f): return 'memcpy/memset'
    
    if 'alloc' in f or 'malloc' in f or 'free' in f: return 'allocator'
    return 'elementwise/own loops'
tot=len(samples)
by=collections.Counter(); byl=collections.Counter(); byleaf=collections.Counter()
for s in samples:
    L=layer(s); K=leaf(s)
    by[(L,K)]+=1; byl[L]+=1; byleaf[K]+=1
print("samples",tot)
print("\n## by category"); 
for k,v in byleaf.most_common(): print(f"{100*v/tot:5.1f}%  {k}")
print("\n## by layer"); 
for k,v in byl.most_common(25): print(f"{100*v/tot:5.1f}%  {k}")
print("\n## layer x category (>=1%)")
for (l,k),v in by.most_common():
    if v/tot>=0.01: print(f"{100*v/tot:5.1f}%  {l}  |  {k}")
